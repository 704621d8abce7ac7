"""The conventions every track3d command line follows (track3d, track3d-train, benchmarks).

- every flag has help and shows its default (:class:`HelpFormatter` appends "(default: X)"
  where the help text does not already say it);
- one name per flag across CLIs (``--checkpoint``, ``--max-steps``, ``--quiet``); older names
  stay as hidden aliases (:func:`hidden_alias`);
- a user's mistake is one line on stderr and exit 2 (:func:`run_main`), never a traceback;
  a command-line mistake too (:class:`ArgumentParser`: the error and where the help is, not
  the whole usage block).
"""
from __future__ import annotations

import argparse
import contextlib
import sys
import warnings
from pathlib import Path
from typing import Callable

__all__ = ["ArgumentParser", "one_line_warnings", "Terminated", "terminate_as_interrupt", "HelpFormatter", "apply_formatter", "hidden_alias", "run_main", "USER_ERRORS", "thread_count", "allowed_cpu",
           "missing_extra", "exit_for_missing_extra", "package_version", "bounded"]


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Raw descriptions, and "(default: X)" after any help that does not mention its default."""

    def _get_help_string(self, action: argparse.Action) -> str:
        h = action.help or ""
        if h is argparse.SUPPRESS or "%(default)" in h or "default" in h.lower():
            return h
        d = action.default
        if d is None or d is False or d is argparse.SUPPRESS or isinstance(action, argparse._HelpAction) \
                or action.option_strings == [] or d == []:
            return h
        return f"{h} (default: %(default)s)"


class ArgumentParser(argparse.ArgumentParser):
    """argparse with the conventions: HelpFormatter by default, and a usage mistake printed as
    one line (``prog: error: ... (see prog --help)``), exit 2. argparse's default prints the
    whole usage block first, a dozen lines for the bigger commands, burying the error.
    Sub-command parsers are of the same class (argparse makes them with type(parent))."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # argparse's hook; must not return
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_args(self, args=None, namespace=None):
        # an unknown flag is the sub-command's mistake: argparse reports it from the top parser,
        # whose --help does not list the sub-command's flags (`track3d track --trakcer` pointed
        # to `track3d --help`)
        ns, extras = self.parse_known_args(args, namespace)
        if extras:
            self._chosen(ns).error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def _chosen(self, ns) -> argparse.ArgumentParser:
        """The deepest sub-command parser `ns` went through (self without sub-commands)."""
        parser = self
        while True:
            sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
            name = None if sub is None or sub.dest == argparse.SUPPRESS else getattr(ns, sub.dest, None)
            if name not in getattr(sub, "choices", {}):
                return parser
            parser = sub.choices[name]


def bounded(kind: type = int, low: float | None = None, above: float | None = None,
            high: float | None = None) -> Callable[[str], float]:
    """argparse type: an int or float that is >= low, > above and <= high (each optional; NaN
    never passes). A count of 0 or -5 or a learning rate of -1 used to run and write a wrong or
    empty result, or end in a ZeroDivisionError deep inside."""
    what = "an integer" if kind is int else "a number"
    rule = " and ".join(r for r in (low is not None and f">= {low}", above is not None and f"> {above}",
                                     high is not None and f"<= {high}") if r)

    def parse(text: str):
        try:
            v = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {what} {rule}, got {text!r}") from None
        if v != v or (low is not None and v < low) or (above is not None and v <= above) \
                or (high is not None and v > high):
            raise argparse.ArgumentTypeError(f"expected {what} {rule}, got {text!r}")
        return v
    parse.__name__ = f"{what} {rule}"
    return parse


def thread_count(text: str) -> int:
    """argparse type of every --threads: an integer from 1 to track3d.threads.max_threads()."""
    from .threads import check_threads, threads_rule

    try:
        return check_threads(int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {threads_rule()}, got {text!r}") from None


def allowed_cpu(text: str) -> int:
    """argparse type of a benchmark's --cpu: one of the CPUs the process was started on
    (track3d.machine.START_CPUS; `taskset` chooses them). Another CPU used to be taken silently:
    the run left its taskset or, for a CPU that does not exist, ran unpinned while its record
    said pinned."""
    from .machine import START_CPUS

    allowed = ", ".join(map(str, START_CPUS))
    if not text.strip().isdigit() or int(text) not in START_CPUS:
        raise argparse.ArgumentTypeError(f"CPU {text} is not allowed: this process may run on {allowed}")
    return int(text)


def package_version() -> str:
    """The installed track3d version (`--version` of all three commands); "unknown" in a bare
    checkout without installed metadata."""
    try:
        from importlib.metadata import version

        return version("track3d")
    except Exception:
        return "unknown"


def apply_formatter(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Give `parser` and all its sub-command parsers the HelpFormatter, and each sub-command
    without a description its one-line help as one (argparse shows that help only in the
    parent's list, so `track3d-sim stats --help` had not said what stats does)."""
    parser.formatter_class = HelpFormatter
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {c.dest: c.help for c in action._choices_actions}
            for name, sub in action.choices.items():
                if not sub.description and helps.get(name):
                    sub.description = helps[name]
                apply_formatter(sub)
    return parser


def hidden_alias(parser: argparse.ArgumentParser, flag: str, dest: str, **kwargs) -> None:
    """An old flag name that still works but is not shown in --help."""
    parser.add_argument(flag, dest=dest, help=argparse.SUPPRESS, default=argparse.SUPPRESS, **kwargs)


def missing_extra(e: ModuleNotFoundError, extras: dict[str, str]) -> str | None:
    """The one-line reason for a module that an extra installs (`extras`: top-level module ->
    extra name): "needs the sim extra: pip install 'track3d[sim]' (missing: tqdm)". None for
    any other module: that is a bug, not the user's install, and keeps its traceback."""
    top = (e.name or "").split(".")[0]
    extra = extras.get(top)
    if extra is None:
        return None
    return f"needs the {extra} extra: pip install 'track3d[{extra}]' (missing: {top})"


def exit_for_missing_extra(e: ModuleNotFoundError, extras: dict[str, str], prog: str) -> int:
    """In a command's `except ModuleNotFoundError`: print `prog: error: needs the X extra ...`
    and return exit code 2, or re-raise `e` when no extra installs the module."""
    hint = missing_extra(e, extras)
    if hint is None:
        raise e
    print(f"{prog}: error: {hint}", file=sys.stderr)
    return 2


def _user_errors() -> tuple:
    errs: list = [ValueError, FileNotFoundError, NotADirectoryError, PermissionError]
    for mod, name in (("track3d.dataset", "DatasetError"), ("track3d.onnxmodel", "ModelError"),
                      ("track3d.trackers2d", "TrackerUnavailable"), ("track3d.estimators", "EstimatorUnavailable")):
        try:
            errs.append(getattr(__import__(mod, fromlist=[name]), name))
        except ImportError:
            pass
    return tuple(errs)


USER_ERRORS = _user_errors()


# the packages whose warnings a console script prints as one line (one_line_warnings)
OWN_PACKAGES = ("track3d", "track3d_sim", "track3d_train")


def _own(filename: str) -> bool:
    """Whether a warning was raised in one of OWN_PACKAGES' files (a module or a subpackage's)."""
    parts = Path(str(filename)).parts[-3:-1]
    return any(part in OWN_PACKAGES for part in parts)


@contextlib.contextmanager
def one_line_warnings(prog: str):
    """Around a console script's main(): a warning raised in track3d's own code prints as one line,
    ``<prog>: warning: <message>``, as the errors do, where Python prints two (the path of the
    installed module and the warnings.warn call's source line: a dataset's clipped labels read
    '/.../site-packages/track3d/dataset.py:790: DatasetWarning: ...'). Other code's warnings keep
    Python's form. Only the text of a shown warning changes (warnings.formatwarning): a recorder
    (pytest's, catch_warnings(record=True)) still gets the warning itself; the formatter before is
    back on exit."""
    before = warnings.formatwarning

    def text(message, category, filename, lineno, line=None):
        if not _own(filename):
            return before(message, category, filename, lineno, line)
        return f"{prog}: warning: {' '.join(str(message).splitlines())}\n"

    warnings.formatwarning = text
    try:
        yield
    finally:
        if warnings.formatwarning is text:
            warnings.formatwarning = before


class Terminated(KeyboardInterrupt):
    """SIGTERM inside `terminate_as_interrupt`: unwinds as Ctrl-C does (each `finally` and the
    cleanup of a half-written sequence run), then exits 143 instead of 130."""


@contextlib.contextmanager
def terminate_as_interrupt():
    """While inside (a console script's main, in the main thread), SIGTERM raises Terminated:
    Python's default had ended the process at once, exit 143 without a word, a half-written
    result folder left behind. The handler that was there is put back on exit."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handle(signum, frame):
        raise Terminated

    try:
        if signal.getsignal(signal.SIGTERM) is signal.SIG_IGN:   # started to ignore it (nohup-like): it stays so
            yield
            return
        before = signal.signal(signal.SIGTERM, handle)
    except (ValueError, OSError):   # no signals here (an embedded interpreter)
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before if before is not None else signal.SIG_DFL)


def interrupt_exit(prog: str, e: KeyboardInterrupt, how: str = "") -> int:
    """Print one line for an interrupted command (`how`: what to do now) and return its exit code."""
    what = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
    print(f"{prog}: {what}{': ' + how if how else ''}", file=sys.stderr)
    return 143 if isinstance(e, Terminated) else 130


def run_main(main: Callable[[], int | None], prog: str) -> int:
    """Run a script's main(): the errors a user causes become one line and exit 2."""
    try:
        with terminate_as_interrupt():
            return int(main() or 0)
    except USER_ERRORS as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        return interrupt_exit(prog, e)
