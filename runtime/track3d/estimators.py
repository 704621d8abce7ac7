"""3D box estimators behind one protocol, and a registry of them by name.

    box3d = estimator.estimate(points, category)   # points (n, 3) float32, n >= 1 -> (6,) float64

An estimator with the class attribute ``takes_bounds = True`` also accepts
``estimate(points, category, bounds=)``, bounds the (2, 3) [min; max] of the points, which the
loop's frustum pass has already computed (A3BoxNet's "frustum" coding reads them). One with
``amodal = True`` answers with a guess of the whole body, seen and hidden: the loop then takes
the faces the sensor sees from the returns and keeps only its hidden back face
(``Track3D(measured_faces=True)``, track3d.boxes.fit_measured_faces); other estimators' boxes
are reported as they are.

Built-in names: ``"baseline"`` (the paper's 3D tracking baseline, section V-A: the minimum
enclosing axis-aligned box of the frustum points, ``track3d.boxes.box3d_from_points``) and
``"a3boxnet"`` (the shipped A3BoxNet ONNX model, ``track3d.boxnet``, loaded lazily) and
``"none"`` (:class:`NoEstimator`: 2D only, the null estimator in the manner of the GOT-10k
toolkit's IdentityTracker, so that a 2D tracker is evaluated by the same loop and toolkit).
"""
from __future__ import annotations

import importlib
from typing import Callable, Protocol, runtime_checkable

import numpy as np

from .boxes import box3d_from_points
from .frames import check_category, check_estimator_points, check_point_bounds, point_bounds

__all__ = ["BoxEstimator", "BaselineEstimator", "NoEstimator", "EstimatorUnavailable", "create_estimator",
           "available_estimators", "register_estimator", "estimator_factory"]


class EstimatorUnavailable(RuntimeError):
    """A registered estimator cannot be built here (its model file or module is missing)."""


@runtime_checkable
class BoxEstimator(Protocol):
    """Frustum points -> axis-aligned 3D box [cx, cy, cz, sx, sy, sz] in the camera frame."""

    def estimate(self, points: np.ndarray, category: int) -> np.ndarray:
        """points (n, 3) float32 with n >= 1; category: coarse category index -> (6,) float64.

        Raises ValueError on points or a category outside the contract (track3d.frames)."""


class BaselineEstimator:
    """Minimum enclosing box of the frustum points (paper V-A); ignores the category."""

    name = "baseline"

    def __init__(self, threads: int = 1):  # threads: accepted for a uniform factory signature
        del threads

    def __repr__(self) -> str:
        return "BaselineEstimator()"

    def estimate(self, points: np.ndarray, category: int = -1) -> np.ndarray:
        check_category(category)
        p = np.asarray(points)
        p = check_estimator_points(p, p.dtype if p.dtype in (np.float32, np.float64) else np.float64, finite=False)
        # One pass: the enclosing box's corners carry both the check (NaN / inf / range show up
        # in min / max) and the answer (the box of the two corners is the box of all points).
        lo, hi = point_bounds(p)
        check_point_bounds(lo, hi)
        return box3d_from_points(np.stack([lo, hi]))


class NoEstimator:
    """No 3D box: the loop runs the 2D tracker alone (no frustum, no fusion, no points read).

    ``needs_points = False`` is what Track3D and the evaluation look at; an estimator without
    the attribute needs points."""

    name = "none"
    needs_points = False

    def __init__(self, threads: int = 1):  # threads: accepted for a uniform factory signature
        del threads

    def __repr__(self) -> str:
        return "NoEstimator()"

    def estimate(self, points: np.ndarray, category: int = -1) -> np.ndarray:
        """Never called by Track3D; answers "no box" (nan) to anyone who calls it."""
        return np.full(6, np.nan)


def _a3boxnet(**options) -> BoxEstimator:
    try:
        mod = importlib.import_module("track3d.boxnet")
        create = getattr(mod, "A3BoxNetEstimator")
    except (ImportError, AttributeError) as e:
        raise EstimatorUnavailable(f"A3BoxNet model not available: track3d.boxnet cannot be loaded ({e})") from None
    from .onnxmodel import ModelError   # loaded with track3d.boxnet above
    from .plugins import call_factory

    try:
        # through call_factory with the real signature: this wrapper's **options would hide it
        # and a wrong name would be a bare TypeError without the list of options it takes
        return call_factory("3D box estimator", "a3boxnet", create, options)
    except (FileNotFoundError, OSError, ModelError) as e:   # no shipped model yet, or a bad file
        raise EstimatorUnavailable(f"A3BoxNet model not available: {e}") from None


_REGISTRY: dict[str, Callable[..., BoxEstimator]] = {"baseline": BaselineEstimator, "a3boxnet": _a3boxnet,
                                                         "none": NoEstimator}


_BUILT_IN = frozenset(_REGISTRY)


def register_estimator(name: str, factory: Callable[..., BoxEstimator], replace: bool = False) -> None:
    """Add an estimator: ``factory(**options)`` returns a :class:`BoxEstimator`. A built-in name
    is refused unless `replace` (track3d.trackers2d.register_tracker says why)."""
    from .plugins import check_registration

    check_registration("estimator", name, factory, _BUILT_IN, replace)
    _REGISTRY[name.lower()] = factory


def _load_plugins() -> None:
    from .plugins import ESTIMATOR_GROUP, load_entry_points

    load_entry_points(ESTIMATOR_GROUP, register_estimator)


def available_estimators() -> list[str]:
    """Registered estimator names, plug-ins included."""
    _load_plugins()
    return sorted(_REGISTRY)


def estimator_factory(name: str) -> Callable[..., BoxEstimator]:
    """The factory registered as `name` (plug-ins loaded when it is not yet known); ValueError
    listing the names there are."""
    factory = _REGISTRY.get(str(name).lower())
    if factory is None:
        _load_plugins()
        factory = _REGISTRY.get(str(name).lower())
    if factory is None:
        raise ValueError(f"unknown 3D box estimator {name!r}; available: {', '.join(available_estimators())} "
                         "(a plug-in: --plugin MODULE or an entry point in the track3d.estimators group)")
    return factory


def create_estimator(name: str, **options) -> BoxEstimator:
    """Build the estimator registered as `name` (e.g. ``create_estimator("a3boxnet", threads=1)``)."""
    from .plugins import call_factory, check_built

    factory = estimator_factory(name)
    return check_built("3D box estimator", name, call_factory("3D box estimator", name, factory, options),
                       ("estimate",))
