"""A training run stopped by SIGTERM or SIGINT (Ctrl-C) writes its checkpoint before it ends.

The loops of A3BoxNet, EdgeTrack and SiamFC run inside ``StopOnSignal``: a signal only sets a
flag, the loop sees it at the next step boundary, writes its checkpoint (the state a resumed run
goes on from exactly) and raises ``TrainingInterrupted``. Without it a kill lost up to a
checkpoint interval of work (EdgeTrack's three minutes; a run killed at 20 s restarted at step 0).

A second signal while the checkpoint is being written ends the run at once (KeyboardInterrupt):
the checkpoints are written atomically, so the previous one stays whole. A signal the process
was started ignoring (nohup, a background job of a non-interactive shell) stays ignored.
"""
from __future__ import annotations

import signal
import threading

__all__ = ["SIGNALS", "StopOnSignal", "Interrupted", "TrainingInterrupted", "RESUMABLE", "interrupted_message"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Interrupted(KeyboardInterrupt):
    """A command stopped by the signal `signum`, having cleaned up. A KeyboardInterrupt, so that
    a caller that does not know it stops as on Ctrl-C."""

    def __init__(self, signum: int, text: str = ""):
        self.signum = int(signum)
        super().__init__(text or signal.Signals(self.signum).name)

    @property
    def exit_code(self) -> int:
        """The shell's code of a process ended by the signal: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


class TrainingInterrupted(Interrupted):
    """A training loop stopped on `signum` after writing `checkpoint` at `step`."""

    def __init__(self, signum: int, step: int, checkpoint):
        self.step, self.checkpoint = int(step), str(checkpoint)
        super().__init__(signum, f"{signal.Signals(int(signum)).name} at step {self.step}: "
                                 f"checkpoint {self.checkpoint} written")


# the track3d-train commands that continue where an interrupted run stopped
RESUMABLE = {("boxnet", "train"), ("edgetrack", "train"), ("siamfc", "train"), ("recipe", "run")}


def interrupted_message(e: KeyboardInterrupt, argv: list[str]) -> tuple[str, int]:
    """(one line, exit code) for a track3d-train command `argv` (its words after track3d-train)
    ended by Ctrl-C or a signal: where a training stopped, and whether running the same command
    again resumes. The code is 128 + the signal, 130 for a bare KeyboardInterrupt (Ctrl-C)."""
    head = "interrupted"
    if isinstance(e, TrainingInterrupted):
        head += f" ({signal.Signals(e.signum).name}) at step {e.step}, checkpoint {e.checkpoint} written"
    elif isinstance(e, Interrupted):
        head += f" ({signal.Signals(e.signum).name})"
    if tuple(argv[:2]) in RESUMABLE:
        head += (": run it again without --no-resume to resume" if "--no-resume" in argv
                 else ": run the same command again to resume")
    return head, getattr(e, "exit_code", 130)


class StopOnSignal:
    """Context manager: while inside, SIGINT and SIGTERM set ``signum`` (true when set) instead of
    ending the process. Only the main thread can catch signals: elsewhere it does nothing."""

    def __init__(self):
        self.signum: int | None = None
        self._old: dict = {}

    def __enter__(self) -> "StopOnSignal":
        if threading.current_thread() is threading.main_thread():
            for s in SIGNALS:
                if signal.getsignal(s) is not signal.SIG_IGN:
                    self._old[s] = signal.signal(s, self._handle)
        return self

    def _handle(self, signum, frame) -> None:
        # a second Ctrl-C: stop now. A second SIGTERM is not a person's hurry: a recipe killed with
        # kill -9 sends its step's death signal once per thread the orphan is handed to, and two
        # had ended the training before its checkpoint (a review)
        if self.signum is not None and signum == signal.SIGINT:
            raise KeyboardInterrupt
        if self.signum is None:
            self.signum = signum

    def __exit__(self, *exc) -> bool:
        for s, old in self._old.items():
            signal.signal(s, signal.SIG_DFL if old is None else old)
        self._old = {}
        return False

    def __bool__(self) -> bool:
        return self.signum is not None

    def interrupted(self, step: int, checkpoint) -> TrainingInterrupted:
        """The exception to raise once the checkpoint is written."""
        return TrainingInterrupted(self.signum, step, checkpoint)
