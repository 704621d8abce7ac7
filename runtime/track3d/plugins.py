"""Plug-ins: a user's 2D trackers and box estimators, found by entry point or imported by name.

Two ways in, both ending in ``register_tracker`` / ``register_estimator``:

- an installed distribution declares entry points (pyproject.toml)::

      [project.entry-points."track3d.trackers"]
      tm = "my_package.tm:TemplateTracker"          # name = a factory(**options) -> Tracker2D
      [project.entry-points."track3d.estimators"]
      mybox = "my_package.box:make_estimator"

  They are loaded the first time the registry is listed or asked for a name it lacks;
- ``--plugin MODULE`` (or ``--plugin path/to/file.py``) on the CLI, ``import_plugin`` in
  Python: the module is imported and registers itself at import.

A plug-in that fails to load is reported as a warning (stderr), never a crash of the others.
"""
from __future__ import annotations

import importlib
import importlib.metadata
import importlib.util
import sys
import warnings
from pathlib import Path
from typing import Callable

__all__ = ["TRACKER_GROUP", "ESTIMATOR_GROUP", "load_entry_points", "import_plugin", "call_factory", "check_built",
           "check_registration", "plugin_frame", "takes_option"]

TRACKER_GROUP = "track3d.trackers"
ESTIMATOR_GROUP = "track3d.estimators"
_loaded: set[str] = set()
_imported: set[str] = set()   # plug-in modules imported by dotted name (files: track3d_plugin_<stem>)


def _entry_points(group: str):
    try:
        return list(importlib.metadata.entry_points(group=group))
    except TypeError:  # very old importlib.metadata: a dict of groups
        return list(importlib.metadata.entry_points().get(group, []))


def load_entry_points(group: str, register, force: bool = False) -> list[str]:
    """Register every entry point of `group` with `register(name, factory)` (once per process
    unless `force`); returns the names registered."""
    if group in _loaded and not force:
        return []
    _loaded.add(group)
    names = []
    for ep in _entry_points(group):
        try:
            factory = ep.load()
            register(ep.name, factory)
            _imported.add(getattr(factory, "__module__", "") or "")
            names.append(ep.name)
        except Exception as e:  # a broken plug-in must not take the registry down
            warnings.warn(f"track3d plug-in {ep.name!r} ({ep.value}) of {group} cannot be loaded: "
                          f"{type(e).__name__}: {e}", RuntimeWarning, stacklevel=2)
    return names


def import_plugin(spec: str):
    """Import a plug-in module by dotted name or .py file path; it registers itself.

    Raises ValueError (one line) when it cannot be imported."""
    p = Path(spec)
    try:
        if spec.endswith(".py"):
            if not p.is_file():
                raise ValueError(f"plug-in file {spec} does not exist")
            name = f"track3d_plugin_{p.stem}"
            mod_spec = importlib.util.spec_from_file_location(name, p)
            module = importlib.util.module_from_spec(mod_spec)
            sys.modules[name] = module
            mod_spec.loader.exec_module(module)
            return module
        module = importlib.import_module(spec)
        _imported.add(module.__name__)
        return module
    except ValueError:
        raise
    except Exception as e:
        hint = ""
        if isinstance(e, ModuleNotFoundError) and e.name == spec and Path(f"{spec}.py").is_file():
            hint = f" (the file {spec}.py is here: give its path, --plugin ./{spec}.py)"
        raise ValueError(f"plug-in {spec!r} cannot be imported: {type(e).__name__}: {e}{hint}") from None


def takes_option(factory: Callable, option: str) -> bool:
    """Whether factory(**{option: ...}) binds: a named parameter or **kwargs."""
    import inspect

    try:
        params = inspect.signature(factory).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(p.name == option and p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) or p.kind == p.VAR_KEYWORD
               for p in params)


def call_factory(kind: str, name: str, factory: Callable, options: dict):
    """factory(**options), with a wrong option name or value as one ValueError line saying
    which options the factory takes (never a TypeError traceback)."""
    import inspect

    try:
        sig = inspect.signature(factory)
    except (TypeError, ValueError):
        sig = None
    if sig is not None:
        try:
            sig.bind(**options)
        except TypeError as e:
            takes = [p.name for p in sig.parameters.values()
                     if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
            raise ValueError(f"bad option for the {kind} {name!r}: {e} (it takes: "
                             f"{', '.join(takes) or 'no options'})") from None
    try:
        return factory(**options)
    except TypeError as e:
        raise ValueError(f"bad option for the {kind} {name!r}: {e}") from None


def check_registration(kind: str, name, factory, built_in: frozenset, replace: bool) -> None:
    """A registration's name and factory, or one ValueError / TypeError line."""
    if not name or not isinstance(name, str):
        raise ValueError(f"a {kind} name is a non-empty string")
    if not callable(factory):
        raise TypeError("factory must be callable")
    if name.lower() in built_in and not replace:
        raise ValueError(f"{name!r} is a built-in {kind} of track3d: register yours under another name "
                         f"(or pass replace=True to run it in the built-in's place)")


def check_built(kind: str, name: str, obj, methods: tuple[str, ...]):
    """`obj` as a factory built it, or one ValueError line when it lacks the protocol's methods
    (a factory without `return`, a class with `upate`: they had failed mid-run with a traceback)."""
    missing = [m for m in methods if not callable(getattr(obj, m, None))]
    if obj is None or missing:
        got = "None (does the factory return what it builds?)" if obj is None else type(obj).__name__
        raise ValueError(f"the {kind} {name!r} built {got}, which has no "
                         f"{', '.join(m + '()' for m in (missing or methods))}: the protocol of a {kind} "
                         f"is {', '.join(m + '()' for m in methods)} (docs/runtime.md, \"Plug-ins\")")
    return obj


def plugin_frame(exc: BaseException) -> str | None:
    """'file.py:LINE in FUNCTION' of the innermost frame of `exc`'s traceback that lies in a
    plug-in module's file (imported by import_plugin or an entry point outside track3d), or None
    when the error did not pass through one: the CLI names the plug-in instead of a traceback."""
    import traceback

    package = Path(__file__).resolve().parent
    files = {}
    for mod in list(sys.modules.values()):
        f = getattr(mod, "__file__", None)
        name = getattr(mod, "__name__", "") or ""
        # a plug-in package's submodules too (--plugin mypkg whose tracker lives in mypkg.trk)
        if f and (name.startswith("track3d_plugin_")
                  or any(name == p or name.startswith(p + ".") for p in _imported if p)):
            files[str(Path(f).resolve())] = name
    found = None
    for fr in traceback.extract_tb(exc.__traceback__):
        path = str(Path(fr.filename).resolve())
        if path in files and not path.startswith(str(package)):
            found = f"{Path(fr.filename).name}:{fr.lineno} in {fr.name}"
    return found
