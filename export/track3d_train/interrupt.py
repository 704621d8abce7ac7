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

__all__ = ["SIGNALS", "StopOnSignal", "TrainingInterrupted"]

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class TrainingInterrupted(KeyboardInterrupt):
    """A training loop stopped on `signum` after writing `checkpoint` at `step`. A
    KeyboardInterrupt, so that a caller that does not know it stops as on Ctrl-C."""

    def __init__(self, signum: int, step: int, checkpoint):
        self.signum, self.step, self.checkpoint = int(signum), int(step), str(checkpoint)
        super().__init__(f"{signal.Signals(self.signum).name} at step {self.step}: "
                         f"checkpoint {self.checkpoint} written")

    @property
    def exit_code(self) -> int:
        """The shell's code of a process ended by the signal: 130 for SIGINT, 143 for SIGTERM."""
        return 128 + self.signum


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
        if self.signum is not None:   # the second: stop now
            raise KeyboardInterrupt
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
