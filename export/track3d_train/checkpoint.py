"""Reading a training checkpoint and telling the user which network it belongs to.

A3BoxNet checkpoints hold ``model_config``; SiamFC and EdgeTrack checkpoints both hold
``config``, told apart by a key only their own config has (SiamFC's ``variant``, EdgeTrack's
``widths``; both since the first version of each). Giving one to another's exporter is a
one-line ValueError that names the right command, not a KeyError or a state-dict mismatch.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable

__all__ = ["load_checkpoint_dict", "save_checkpoint", "write_text_atomic", "network_of", "SIGNATURES",
           "random_state", "restore_random_state", "flag_differences", "refuse_other_flags",
           "refuse_other_data", "check_run_folder", "RunLock"]


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


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write `text` to `path` through a temporary file beside it (a kill leaves the old file whole)."""
    import os

    p = Path(path)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, p)


def check_run_folder(out: str | Path) -> Path:
    """A training's --out: a folder or nothing yet; an existing file is a one-line ValueError (it
    had been FileExistsError's traceback)."""
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise ValueError(f"--out {p} is a file, not a run folder: give a folder (new or a run's own)")
    return p


def _flag_text(flag: str, value, invert: bool = False) -> str:
    if isinstance(value, bool):   # a switch: given or not (`invert`: the flag turns the setting off)
        return flag if value != invert else f"no {flag}"
    if isinstance(value, (list, tuple)):
        return f"{flag} {' '.join(f'{v:g}' if isinstance(v, float) else str(v) for v in value)}"
    return f"{flag} {value:g}" if isinstance(value, float) else f"{flag} {value}"


def flag_differences(saved: dict, now: dict, flags: dict) -> list[str]:
    """The flags of a resumed run whose value differs from its checkpoint's, as the checkpoint has
    them ("--batch 8", "no --flip-y"). `flags`: setting -> flag, or (flag, True) for a switch that
    turns the setting off (--no-flip); a setting the checkpoint does not record (an older one) is
    not compared."""
    out = []
    for key, flag in flags.items():
        flag, invert = (flag, False) if isinstance(flag, str) else flag
        if key not in saved or key not in now:
            continue
        a, b = saved[key], now[key]
        same = (list(a) == list(b)) if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)) else a == b
        if not same:
            out.append(_flag_text(flag, a, invert))
    return out


def _no_lock(folder: Path, e: OSError) -> None:
    import warnings

    warnings.warn(f"{folder}: no lock against a second trainer on this run folder ({e.strerror or e}): this "
                  "file system does not lock folders; run one trainer per --out", RuntimeWarning, stacklevel=3)


class RunLock:
    """An exclusive lock (fcntl.flock, on the run folder itself: no file left behind) held while a
    training writes its run folder: a second trainer on the same --out is a one-line ValueError
    (two had written the same checkpoint and log, e.g. a recipe run again while the trainer of a
    recipe killed with kill -9 still ran). `acquire` takes it once the folder exists (a training
    checks its inputs before it makes the folder); leaving the `with` block, or the process
    ending in any way, releases it. Without fcntl (not POSIX) there is no lock."""

    def __init__(self):
        self.fd: int | None = None

    def acquire(self, folder: str | Path) -> None:
        import os

        folder = Path(folder)
        if self.fd is not None or not folder.is_dir():
            return
        try:
            import fcntl
        except ImportError:
            return
        try:
            fd = os.open(str(folder), os.O_RDONLY)
        except OSError as e:
            _no_lock(folder, e)
            return
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:   # another process (or this one) holds it
            os.close(fd)
            raise ValueError(f"another training is running in {folder}: wait for it to end (or stop it), "
                             "or give another --out") from None
        except OSError as e:   # a file system without flock on a folder (NFS emulates it with fcntl
            os.close(fd)       # locks, which need a file open for writing): train, unguarded, and say so
            _no_lock(folder, e)
            return
        self.fd = fd

    def release(self) -> None:
        import os

        if self.fd is not None:
            os.close(self.fd)   # closing the descriptor releases the lock
            self.fd = None

    def __enter__(self) -> "RunLock":
        return self

    def __exit__(self, *exc) -> bool:
        self.release()
        return False


def refuse_other_flags(ck_path: str | Path, differ: list[str]) -> None:
    """A run resumed with other settings than its checkpoint's: one line naming the flags
    (`flag_differences`), instead of taking them silently."""
    if differ:
        raise ValueError(f"{ck_path} was trained with other flags than this run's: resume with the same "
                         f"flags ({', '.join(differ)}), or start a new --out (or pass --no-resume)")


def refuse_other_data(ck_path: str | Path, cache, saved_hash, hash_now) -> None:
    """A run resumed on another training cache than its checkpoint's (compared by the data's
    hash, not the path's spelling): one line. No recorded hash (an older checkpoint): not compared."""
    if saved_hash and hash_now and saved_hash != hash_now:
        raise ValueError(f"{ck_path} was trained on other data than {cache}: resume with the run's own cache, "
                         "or start a new --out (or pass --no-resume)")


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
