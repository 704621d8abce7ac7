"""The simulator's one exception type: a message that names the problem."""


class SimError(Exception):
    """A bad argument, a bad user mesh or an output folder in an unexpected state."""
