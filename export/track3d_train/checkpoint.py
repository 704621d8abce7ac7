"""Reading a training checkpoint and telling the user which network it belongs to.

A3BoxNet checkpoints hold ``model_config``; SiamFC and EdgeTrack checkpoints both hold
``config``, told apart by a key only their own config has (SiamFC's ``variant``, EdgeTrack's
``widths``; both since the first version of each). Giving one to another's exporter is a
one-line ValueError that names the right command, not a KeyError or a state-dict mismatch.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

__all__ = ["load_checkpoint_dict", "save_checkpoint", "network_of", "SIGNATURES", "random_state",
           "restore_random_state"]


def _config_with(key: str, config: str = "config") -> Callable[[dict], bool]:
    return lambda ck: isinstance(ck.get(config), dict) and key in ck[config]


# network -> (is a checkpoint dict one of it?, the command that exports it)
SIGNATURES: dict[str, tuple[Callable[[dict], bool], str]] = {
    "A3BoxNet": (lambda ck: "model_config" in ck, "track3d-train boxnet export"),
    "SiamFC": (_config_with("variant"), "track3d-train siamfc export"),
    "EdgeTrack": (_config_with("widths"), "track3d-train edgetrack export"),
}


def save_checkpoint(path: str | Path, ck: dict) -> None:
    """torch.save `ck` to `path` through a temporary file beside it, so that a run killed while
    saving leaves the previous checkpoint whole."""
    import os

    import torch

    p = Path(path)
    tmp = p.with_name(p.name + ".tmp")
    torch.save(ck, str(tmp))
    os.replace(tmp, p)


def random_state(rng) -> dict:
    """The random streams a resumed run must continue, for its checkpoint: the numpy Generator
    `rng` (a pair sampler's: data order and augmentation) and torch's CPU generator. Reseeding on
    resume instead (from the step, say) makes the result depend on when the run was killed."""
    import torch

    return {"numpy": rng.bit_generator.state, "torch": torch.get_rng_state()}


def restore_random_state(rng, state: dict) -> None:
    """Put `random_state`'s streams back: `rng` continues where the checkpointed run's stood."""
    import torch

    rng.bit_generator.state = state["numpy"]
    torch.set_rng_state(state["torch"])


def network_of(ck) -> str | None:
    """The network a loaded checkpoint belongs to (a key of SIGNATURES), or None."""
    if not isinstance(ck, dict) or "model" not in ck:
        return None
    return next((name for name, (match, _) in SIGNATURES.items() if match(ck)), None)


def load_checkpoint_dict(path: str | Path, network: str) -> dict:
    """torch.load a checkpoint of `network` (a key of SIGNATURES) and check it is one."""
    import torch

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"checkpoint {p} does not exist")
    try:
        ck = torch.load(str(p), map_location="cpu", weights_only=False)
    except Exception as e:  # not a torch file at all
        raise ValueError(f"{p} is not a PyTorch checkpoint ({type(e).__name__}: {str(e).splitlines()[0][:120]})") from None
    found = network_of(ck)
    if found == network:
        return ck
    if found is not None:
        raise ValueError(f"{p} is {_a(found)} checkpoint, not {_a(network)} one: export it with `{SIGNATURES[found][1]}`")
    raise ValueError(f"{p} is not {_a(network)} checkpoint (nor a training checkpoint of another track3d network)")


def _a(name: str) -> str:
    return ("an " if name[0] in "AEIOU" else "a ") + name
