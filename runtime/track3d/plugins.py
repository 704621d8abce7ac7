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

__all__ = ["TRACKER_GROUP", "ESTIMATOR_GROUP", "load_entry_points", "import_plugin", "call_factory"]

TRACKER_GROUP = "track3d.trackers"
ESTIMATOR_GROUP = "track3d.estimators"
_loaded: set[str] = set()


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
        return importlib.import_module(spec)
    except ValueError:
        raise
    except Exception as e:
        raise ValueError(f"plug-in {spec!r} cannot be imported: {type(e).__name__}: {e}") from None


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
