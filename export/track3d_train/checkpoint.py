"""Reading a training checkpoint and telling the user which network it belongs to.

A3BoxNet checkpoints hold ``model_config``; SiamFC checkpoints ``config``. Giving one to the
other's exporter is a one-line ValueError that names the right command, not a KeyError.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["load_checkpoint_dict", "SIGNATURES"]

# network -> (the key only its checkpoints have, the command that exports it)
SIGNATURES = {"A3BoxNet": ("model_config", "track3d-train boxnet export"),
              "SiamFC": ("config", "track3d-train siamfc export")}


def load_checkpoint_dict(path: str | Path, network: str) -> dict:
    """torch.load a checkpoint of `network` ("A3BoxNet" / "SiamFC") and check it is one."""
    import torch

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"checkpoint {p} does not exist")
    try:
        ck = torch.load(str(p), map_location="cpu", weights_only=False)
    except Exception as e:  # not a torch file at all
        raise ValueError(f"{p} is not a PyTorch checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:120]})") from None
    key = SIGNATURES[network][0]
    if isinstance(ck, dict) and key in ck and "model" in ck:
        return ck
    for other, (k, cmd) in SIGNATURES.items():
        if other != network and isinstance(ck, dict) and k in ck and "model" in ck:
            raise ValueError(f"{p} is a {other} checkpoint, not a {network} one: export it with `{cmd}`")
    raise ValueError(f"{p} is not a {network} checkpoint (no '{key}' and 'model' entries)")
