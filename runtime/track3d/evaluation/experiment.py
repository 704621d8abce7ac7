"""The evaluation experiment of a dataset split, in the manner of the GOT-10k toolkit.

    exp = Experiment("data/small", split="test", result_dir="results", report_dir="reports")
    exp.run(TrackerSpec("kcf", "baseline"))             # writes plain-text results per sequence
    report = exp.report(["kcf+baseline"])               # -> dict (also report.json) + plots

Restart protocol (paper III-C, VOT style): after a frame whose 3D IoU with the ground truth
is zero, the tracker is re-initialised from the ground truth ``restart_skip`` frames later
(default 1: on the next frame; VOT uses 5); frames in between have no output (IoU 0, no
centre error). Every re-initialisation is a restart. Frames where the target is absent are
never scored and never trigger a restart; an initialisation waits for a frame where the
target is present. Initialisation frames report the ground truth and are not scored.

One-pass evaluation (OPE, the 2D toolkits' protocol) is ``restart=False``: one initialisation
on the first frame with the target present, no restarts. 2D only is the null estimator
(``TrackerSpec(tracker, estimator="none")``): the loop runs the 2D tracker alone, reads no
depth, and the scores have no 3D values; so a 2D tracker and a 3D tracker are scored by the
same code on the same threshold grids (metrics).

``init_3d=True`` is 3D single-object tracking's start (KITTI's protocol): every (re-)initialisation
also hands the tracker the ground truth's 3D box of that frame (Track3D.init's ``box3d``). Its
results are of another protocol and are named apart (``<name>-init3d`` by the CLI).
"""
from __future__ import annotations

import hashlib
import json
import shutil
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from ..body_views import BodyViewsParams
from ..boxes import clip_box2d, iou_2d, iou_3d
from ..jsonable import write_json
from ..dataset import Dataset, DatasetError, Sequence
from ..machine import cpu_name
from ..progress import Progress
from ..stereo import StereoCloud, StereoParams
from ..tracker import LOST, STAGES, Track3D
from ..sensor_options import sensor_options
from .draw import OverlayWriter, draw_overlay
from .metrics import (CE2D_THRESHOLDS, CE3D_THRESHOLDS, CI_LEVEL, CONDITIONS, INTERVAL_METRICS, IOU_THRESHOLDS, MOVED,
                      ConditionScore, LostScore, OverallScore, SequenceScore, average_scores, bootstrap_interval,
                      compare_paired, frame_conditions, latency_ms, score_conditions, score_lost, score_sequence)
from .results import (INIT, SKIPPED, SequenceResult, config_differences, read_result, read_run_record, result_folder, run_config_key,
                      write_result, write_run_record)

__all__ = ["TrackerSpec", "Experiment", "run_sequence", "evaluate_2d", "cpu_name", "DEPTH_SOURCES", "labels_digest"]

DEPTH_SOURCES = ("map", "stereo")   # where the point clouds come from (run_sequence's depth)
# Reading results (Experiment._check_protocol): an init row's box is the ground truth's within
# these (2D pixels, 3D metres: the files' 4 / 6 decimals and a script's rounding), and the frame a
# restart follows has an overlap no larger than FAILED_OVERLAP (boxes that touch can overlap by a
# rounding error once written). In memory a frame has failed at an overlap of at most
# ROUNDING_OVERLAP: two boxes that touch face to face give 7e-17, not 0 (the paper restarts at
# zero overlap; a metrics review).
INIT_TOLERANCE = (0.05, 1e-3)
FAILED_OVERLAP = 1e-3
ROUNDING_OVERLAP = 1e-9


@dataclass
class TrackerSpec:
    """A Track3D configuration by registry names; builds one Track3D per sequence.

    The oracle 2D tracker gets the sequence's ground truth (``gt``, ``absent``) automatically;
    estimator "none" is 2D only (its runs are named after the tracker alone).
    """

    tracker: str = "kcf"
    estimator: str = "baseline"
    fusion: bool = True
    weight_3d: float | None = None           # None: by the sequence's depth sensor (fusion_weight_for)
    weight_2d: float | None = None           # None: by the sequence's depth sensor (section_weight_for)
    section_limbs: tuple[float, float, float] | bool | None = None   # None: by the sensor (section_limbs_for); False: off
    measured_faces: bool | None = None         # None: by the sequence's depth sensor (measured_faces_for)
    frustum_margin: float | None = None      # None: by the sequence's depth sensor (frustum_margin_for)
    depth_range: bool = True                 # the sequence's depth sensor range (Sequence.depth_range_m) to Track3D
    depth_smoothing: float | None = None     # None: track3d.tracker.DEPTH_SMOOTHING
    evidence_points: int | None = None       # None: track3d.tracker.EVIDENCE_POINTS
    reacquire_threshold: float | None = None   # None: track3d.tracker.REACQUIRE_THRESHOLD; 0: the tracker's own
    hold_cut_size: float | None = None       # None: track3d.tracker.HOLD_CUT_SIZE
    edge_pad: float | None = None            # None: by the sequence's depth sensor (edge_pad_for)
    front_quantile: float | None = None      # None: by the sequence's depth sensor (front_quantile_for)
    front_filter: tuple[float, float] | bool | None = None   # None: by the sensor (front_filter_for); False: off
    silhouette: float | None = None          # None: by the sequence's depth sensor (silhouette_for)
    outline_share: float | None = None       # None: by the sequence's depth sensor (outline_share_for)
    outline_share_phase: float | None = None   # None: by the sequence's depth sensor (outline_share_phase_for)
    outline_contain: bool | None = None      # None: by the sequence's depth sensor (outline_contain_for)
    texture_trim: bool | None = None         # None: by the sequence's depth sensor (texture_trim_for)
    resume_outline: bool | None = None       # None: by the sequence's depth sensor (resume_outline_for)
    drop_stray: bool | None = None           # None: by the sequence's depth sensor (drop_stray_for)
    dark_side: float | None = None           # None: by the sequence's depth sensor (dark_side_for)
    fusion_cover: float | None = None        # None: by the sequence's depth sensor (fusion_cover_for)
    first_box_fade: float | None = None      # None: by the sequence's depth sensor (first_box_fade_for; used with a first 3D box)
    sun: bool = True                         # the sequence's sun direction (Sequence.sun_direction) to Track3D
    body_views: bool | BodyViewsParams | None = None   # None: by the sequence's depth sensor (body_views_for)
    threads: int = 1
    tracker_options: dict = field(default_factory=dict)
    estimator_options: dict = field(default_factory=dict)
    name: str | None = None

    @property
    def label(self) -> str:
        """The result name: `name`, else <tracker>+<estimator>, each tagged @<model>-<hash8> when
        it runs model files other than the shipped ones (so such a run never replaces those)."""
        if self.name:
            return self.name
        if self.estimator == "none":
            return f"{self.tracker}{_model_tag(self.tracker_options)}"
        return (f"{self.tracker}{_model_tag(self.tracker_options)}+{self.estimator}"
                f"{_model_tag(self.estimator_options)}" + ("" if self.fusion else "-nofusion"))

    def _options(self, kind: str, options: dict) -> dict:
        o = dict(options)
        if kind in ("siamfc", "siamfc-edge", "edgetrack", "a3boxnet"):
            o.setdefault("threads", self.threads)
        return o

    def build(self, seq: Sequence) -> Track3D:
        topts = self._options(self.tracker, self.tracker_options)
        if self.tracker == "oracle":
            topts.update(gt=seq.gt2d, absent=seq.absent)
        eopts = self._options(self.estimator, self.estimator_options)
        if self.estimator == "a3boxnet" and "model" not in eopts:
            eopts.setdefault("depth_sensor", seq.depth_sensor)   # the sensor's own model (boxnet.SENSOR_MODELS)
        t = Track3D.create(seq.camera, self.tracker, self.estimator, tracker_options=topts,
                           estimator_options=eopts,
                           fusion=self.fusion,
                           depth_range_m=seq.depth_range_m if self.depth_range else None,
                           **({} if self.depth_smoothing is None else {"depth_smoothing": self.depth_smoothing}),
                           **({} if self.evidence_points is None else {"evidence_points": self.evidence_points}),
                           **({} if self.reacquire_threshold is None else
                              {"reacquire_threshold": self.reacquire_threshold or None}),
                           **({} if self.hold_cut_size is None else {"hold_cut_size": self.hold_cut_size}),
                           **self.sensor_options(seq.depth_sensor))
        if self.sun:
            t.set_sun(getattr(seq, "sun_direction", None))   # a sequence-like object may not record one
        return t

    def sensor_options(self, depth_sensor: str | None) -> dict:
        """The sensor's defaults (track3d.sensor_options.sensor_options) with this spec's explicit values."""
        opts = sensor_options(depth_sensor)
        opts.update({k: getattr(self, k) for k in opts if getattr(self, k) is not None})
        for key in ("front_filter", "section_limbs"):
            if opts.get(key) is False:   # asked off (None means the sensor's)
                opts[key] = None
        return opts

    def unavailable(self, seq: Sequence) -> str | None:
        """None when this configuration builds here, else why not (a missing model or module):
        benchmarks report such a configuration as skipped instead of failing."""
        from ..estimators import EstimatorUnavailable
        from ..onnxmodel import ModelError
        from ..trackers2d import TrackerUnavailable

        try:
            self.build(seq)
        except (TrackerUnavailable, EstimatorUnavailable, ModelError, ImportError) as e:
            return f"{type(e).__name__}: {e}"
        return None


# Options that name model files (a file, or a prefix <dir>/<name> of a pair such as SiamFC's
# <name>_exemplar/_search.onnx or EdgeTrack's <name>_template/_search.onnx).
_MODEL_OPTIONS = ("model", "exemplar_model", "search_model", "template_model", "backbone", "neckhead")
_PAIR_SUFFIXES = ("_exemplar.onnx", "_template.onnx", "_search.onnx")


def _pair_stem(name: str) -> str:
    for suffix in _PAIR_SUFFIXES + (".onnx",):
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def _model_files(key: str, value: str) -> list[Path]:
    """The existing files an option names: the file itself; for `model` (a prefix, or one file
    of a pair, as the trackers take it) also each file of the pair."""
    p = Path(value)
    files = [p]
    if key == "model":
        files += [p.parent / f"{_pair_stem(p.name)}{s}" for s in _PAIR_SUFFIXES]
    return [f for f in files if f.is_file()]


def _model_tag(options: dict) -> str:
    """'' for the shipped models, else '@<stem>-<8 hex of sha256 over the model files' bytes>'
    (every file a model option names, in path order; a name that is no file counts as text)."""
    import hashlib

    given = [(k, str(options[k])) for k in _MODEL_OPTIONS if options.get(k)]
    if not given:
        return ""
    h = hashlib.sha256()
    files = sorted({f.resolve() for k, g in given for f in _model_files(k, g)})
    for f in files:
        h.update(f.read_bytes())
    for k, g in given:
        if not _model_files(k, g):
            h.update(g.encode())
    stem = _pair_stem(Path(given[0][1]).name)
    stem = "".join(c if c.isalnum() or c in "-_." else "_" for c in stem)[:32]
    return f"@{stem}-{h.hexdigest()[:8]}"


def labels_digest(seq: Sequence) -> str:
    """16 hex digits identifying a sequence's ground truth (2D / 3D labels, absence flags): the run
    record keeps it per sequence, so results are never scored against another dataset's labels."""
    h = hashlib.sha256()
    for a in (seq.gt2d, seq.gt3d, seq.absent):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()[:16]


def _gt_ok(seq: Sequence, i: int) -> bool:
    b = seq.gt2d[i]
    return bool(not seq.absent[i] and np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0)


def run_sequence(track_factory: Callable[[Sequence], Track3D], seq: Sequence, max_frames: int | None = None,
                 restart: bool = True, restart_skip: int = 1, overlay: OverlayWriter | None = None,
                 bar: Progress | None = None, depth: str = "map", init_3d: bool = False,
                 stereo_params: StereoParams | None = None) -> SequenceResult:
    """Track one sequence under the restart protocol; returns its per-frame results.
    init_3d: each initialisation also gets the frame's ground-truth 3D box (3D tracking's start).

    depth: "map" = clouds from the stored depth maps; "stereo" = from the left/right images
    (`track3d.stereo.StereoCloud`, disparity only around the 2D box, timed as tracker time), with
    the matcher's `stereo_params` (default StereoParams())."""
    if restart_skip < 1:
        raise ValueError(f"restart_skip must be >= 1, got {restart_skip}")
    if depth not in DEPTH_SOURCES:
        raise ValueError(f"depth must be one of {', '.join(DEPTH_SOURCES)}, got {depth!r}")
    stereo = None
    if depth == "stereo":
        stereo = StereoCloud(seq.camera, stereo_params)
    n = len(seq) if max_frames is None else min(len(seq), int(max_frames))
    box2d = np.full((n, 4), np.nan)
    raw = np.full((n, 4), np.nan)
    box3d = np.full((n, 6), np.nan)
    status = np.full(n, SKIPPED, dtype=object)
    seconds = np.zeros(n)
    e2e = np.zeros(n)
    stage_ms = np.zeros((n, len(STAGES)))
    track = track_factory(seq)
    needs_points = getattr(track, "needs_points", True)   # False: 2D only, no depth to read
    if not needs_points:
        stereo = None
    seek = getattr(track.tracker2d, "seek", None)
    pending: int | None = 0          # frame index from which to (re-)initialise
    for i in range(n):
        t0 = time.perf_counter()
        image = seq.image(i)
        if not needs_points:
            points = None
        elif stereo is None:
            points = seq.points(i)
        else:
            points = stereo.bind(image, seq.right_image(i))
        t1 = time.perf_counter()
        if pending is not None:
            if i < pending or not _gt_ok(seq, i):
                e2e[i] = t1 - t0
                if bar:
                    bar.update()
                continue
            if seek is not None:
                seek(i)
            if stereo is not None:
                stereo.reset()     # a (re-)start: the body's depth is not the last track's
            if init_3d and needs_points:
                track.init(image, seq.gt2d[i], seq.category, points=points, box3d=seq.gt3d[i])
            else:
                track.init(image, seq.gt2d[i], seq.category, points=points)
            t2 = time.perf_counter()
            box2d[i], raw[i], status[i] = seq.gt2d[i], seq.gt2d[i], INIT
            if needs_points:   # a 2D-only run reports no 3D box, not even the ground truth's
                box3d[i] = seq.gt3d[i]
            seconds[i], e2e[i] = t2 - t1, t2 - t0
            stage_ms[i, STAGES.index("total")] = (t2 - t1) * 1e3
            pending = None
        else:
            out = track.update(image, points)
            t2 = time.perf_counter()
            box2d[i], raw[i], box3d[i], status[i] = out.box2d, out.box2d_raw, out.box3d, out.status
            seconds[i], e2e[i] = out.ms["total"] / 1e3, t2 - t0
            stage_ms[i] = [out.ms[k] for k in STAGES]
            # a 2D-only run has no 3D box: its overlap is the 2D one (a 3D IoU of nan had
            # restarted every other frame)
            overlap = iou_3d(out.box3d, seq.gt3d[i]) if needs_points else iou_2d(out.box2d, seq.gt2d[i])
            if restart and not seq.absent[i] and overlap <= ROUNDING_OVERLAP:
                pending = i + restart_skip
        if overlay is not None:
            overlay.add(draw_overlay(image, seq.camera, box2d[i], raw[i], box3d[i], seq.gt2d[i], seq.gt3d[i],
                                     text=f"{seq.name} #{i + 1} {status[i]}"))
        if bar:
            bar.update(note=str(status[i]))
    return SequenceResult(seq.name, box2d, raw, box3d, status, seconds, e2e, stage_ms)


def _in_image(box2d: np.ndarray, seq) -> np.ndarray:
    """(..., 4) predicted 2D boxes clipped to the sequence's image, as its labels are, for an IoU:
    a box is scored on what of it lies in the image (the GOT-10k toolkit's bound; a tracker's box
    reaching past the border had lost IoU for the part no label can hold; score_sequence does the
    same through its image_size, keeping centre errors on the box as given). nan rows stay nan."""
    return clip_box2d(box2d, seq.camera.width, seq.camera.height)


def _comparison_warnings(names: list[str], runs: dict, lengths: dict) -> list[str]:
    """Warnings that the compared runs are not like for like: different frames, restart settings,
    or results without a run record."""
    out = []
    if len({tuple(sorted(v.items())) for v in lengths.values()}) > 1:
        desc = ", ".join(f"{n}: {sum(lengths[n].values())}" for n in names)
        out.append(f"the runs cover different frames ({desc} result frames): their scores are not comparable")
    settings = {n: (r.get("restart"), r.get("restart_skip"), r.get("restart_overlap")) for n, r in runs.items() if r}
    if len(set(settings.values())) > 1:
        desc = ", ".join(f"{n}: restart={v[0]} skip={v[1]}" + (f" on the {v[2]} overlap" if v[2] else "")
                         for n, v in settings.items())
        out.append(f"the runs used different restart settings ({desc})")
    starts = {n: bool(r.get("init_3d", False)) for n, r in runs.items() if r}
    if len(set(starts.values())) > 1:
        given = ", ".join(n for n, v in starts.items() if v)
        out.append(f"some runs were given the first 3D box ({given}: init_3d) and the others not: another protocol")
    missing = [n for n, r in runs.items() if not r]
    if missing:
        out.append(f"no run record ({', '.join(missing)}): restart settings and models unknown")
    return out


class Experiment:
    """One benchmark: a dataset split, its result and report folders (GOT-10k's Experiment)."""

    def __init__(self, root: str | Path, split: str = "test", result_dir: str | Path = "results",
                 report_dir: str | Path = "reports", sequences: list[str] | None = None,
                 max_frames: int | None = None, restart: bool = True, restart_skip: int = 1,
                 depth: str = "map", max_sequences: int | None = None, init_3d: bool = False,
                 stereo_params: StereoParams | None = None, own_2d: bool = False):
        """sequences: names to run (default: the whole split); max_sequences: only the first N;
        init_3d: every initialisation also gets the ground truth's 3D box (run_sequence);
        stereo_params: the matcher's settings with depth "stereo" (default StereoParams());
        own_2d: score the 2D trackers' own boxes (`_raw_001.txt`, before the loop corrected them),
        in 2D only: with ideal or flash-LiDAR depth the loop's boxes follow the depth's outline
        whatever the tracker did, so the reported boxes say little of the tracker itself."""
        self.dataset = Dataset(root)
        self.split = split
        all_seqs = self.dataset.sequences(split)
        if sequences:
            by_name = {s.name: s for s in all_seqs}
            missing = [s for s in sequences if s not in by_name]
            if missing:
                raise DatasetError(f"sequence(s) {', '.join(missing)} not in split {split!r} of {root} "
                                   f"(has: {', '.join(by_name) or 'none'})")
            all_seqs = [by_name[s] for s in sequences]
        if max_sequences:
            all_seqs = all_seqs[: int(max_sequences)]
        if not all_seqs:
            raise DatasetError(f"split {split!r} of {root} has no sequences")
        self.sequences = all_seqs
        self.result_dir = Path(result_dir)
        self.report_dir = Path(report_dir)
        self.max_frames = max_frames
        self.restart = restart
        self.restart_skip = int(restart_skip)
        if self.restart_skip < 1:   # here, not at the first sequence: no result folder made for nothing
            raise ValueError(f"restart_skip must be >= 1, got {restart_skip}")
        if max_frames is not None and int(max_frames) < 1:
            raise ValueError(f"max_frames must be >= 1, got {max_frames}")
        if depth not in DEPTH_SOURCES:
            raise ValueError(f"depth must be one of {', '.join(DEPTH_SOURCES)}, got {depth!r}")
        self.depth = depth
        self.own_2d = bool(own_2d)
        if stereo_params is not None and depth != "stereo":
            raise ValueError("stereo_params set the matcher of depth='stereo'")
        self.stereo_params = stereo_params
        self.init_3d = bool(init_3d)

    def folder(self, name: str, seq: str) -> Path:
        return result_folder(self.result_dir, self.split, name, seq)

    def run(self, spec: TrackerSpec | Callable[[Sequence], Track3D], name: str | None = None,
            overwrite: bool = True, overlay: str | None = None, overlay_sequences: int = 1,
            quiet: bool = False, replace: bool = False) -> list[Path]:
        """Track every sequence; writes result files, plus overlays (``overlay`` = "gif"/"mp4")
        for the first `overlay_sequences` sequences, and the run record (results.RUN_FILE).
        Returns the result folders.

        Results of another configuration (other names, options, models or restart settings,
        see results.run_config_key) already under `name` raise ValueError unless `replace`, as
        do results of a sequence over another number of frames (a --frames 2 run never silently
        replaces a full one)."""
        if isinstance(spec, TrackerSpec):
            factory, name = spec.build, name or spec.label
        elif name is None:
            raise ValueError("name is required when spec is a factory function")
        else:
            factory = spec
        record = self._run_record(factory, spec)
        old = read_run_record(self.result_dir, self.split, name)
        if old is not None and not replace and run_config_key(old) != run_config_key(record):
            what = "; ".join(config_differences(run_config_key(old), run_config_key(record)))
            raise ValueError(f"{self.result_dir / self.split / name} holds results of another configuration "
                             f"({what}): pick another --name or pass --replace")
        todo = [seq for seq in self.sequences
                if overwrite or not (self.folder(name, seq.name) / f"{seq.name}_status.txt").is_file()]
        if old is not None and not replace:
            self._refuse_other_frames(name, old, todo)
            self._refuse_other_labels(name, old, todo)
        if old is not None and run_config_key(old) == run_config_key(record):
            record["frames"] = {**old.get("frames", {}), **record["frames"]}
            record["labels"] = {**old.get("labels", {}), **record["labels"]}
        folders = []
        for k, seq in enumerate(self.sequences):
            folder = self.folder(name, seq.name)
            if all(t is not seq for t in todo):
                folders.append(folder)
                continue
            n = self._frames(seq)
            record["frames"][seq.name] = n
            made = not folder.exists()
            writer = None
            if overlay and k < overlay_sequences:
                writer = OverlayWriter(folder / f"{seq.name}_overlay.{overlay}")
            try:
                with Progress(n, f"{name} {seq.name}", enabled=False if quiet else None) as bar:
                    res = run_sequence(factory, seq, self.max_frames, self.restart, self.restart_skip, writer, bar,
                                       depth=self.depth, init_3d=self.init_3d, stereo_params=self.stereo_params)
            except BaseException:
                if writer is not None:
                    writer.close()
                if made:   # a folder with no results would stop `track3d eval` of the whole result folder
                    shutil.rmtree(folder, ignore_errors=True)
                raise
            write_result(folder, res)
            if writer is not None:
                writer.close()
            folders.append(folder)
            write_run_record(self.result_dir, self.split, name, record)
        return folders

    def _frames(self, seq: Sequence) -> int:
        return len(seq) if self.max_frames is None else min(len(seq), self.max_frames)

    def _refuse_other_frames(self, name: str, old: dict, todo: list[Sequence]) -> None:
        """A run over other frames of a sequence (e.g. --frames 2 after a full run) would replace
        its results: ValueError naming the difference (the caller passes it unless `replace`)."""
        had = old.get("frames") or {}
        for seq in todo:
            n = self._frames(seq)
            if seq.name in had and had[seq.name] != n:
                raise ValueError(f"{self.result_dir / self.split / name} holds results of {seq.name} over "
                                 f"{had[seq.name]} frames, this run covers {n} (--frames): pick another --name "
                                 "or pass --replace")

    def _refuse_other_labels(self, name: str, old: dict, todo: list[Sequence]) -> None:
        """Results of a sequence of the same name made on other ground truth (another dataset)
        would be replaced by this run: ValueError (the caller passes it unless `replace`)."""
        had = old.get("labels") or {}
        for seq in todo:
            if seq.name in had and had[seq.name] != labels_digest(seq):
                raise ValueError(f"{self.result_dir / self.split / name} holds results of {seq.name} made on "
                                 f"another dataset ({old.get('dataset') or 'unnamed'}): pick another --results "
                                 "or --name, or pass --replace")

    def check_labels(self, name: str) -> list[str]:
        """Raises ValueError when the run record of `name` says its results of a sequence were made
        on other ground truth than this dataset's (scoring them would be a silent wrong answer).
        Returns warnings for records that cannot tell (written before records kept the labels)."""
        rec = read_run_record(self.result_dir, self.split, name)
        if not rec:
            return []
        had = rec.get("labels")
        here = Path(self.dataset.root).resolve().name
        if rec.get("dataset") and rec["dataset"] != here:
            # two datasets may hold the same label files (the same scenes seen by other depth
            # sensors): the digests match, the depth does not; the name is what tells them apart
            raise ValueError(f"the results of {name} were made on another dataset, {rec['dataset']!r}, this is "
                             f"{here!r}: pass the --data they were made on (the same dataset under another "
                             f"folder name: set \"dataset\" in its run.json to {here!r})")
        if had is None:
            return []
        other = [s.name for s in self.sequences if s.name in had and had[s.name] != labels_digest(s)]
        if other:
            raise ValueError(f"the results of {name} for {', '.join(other[:5])}{' ...' if len(other) > 5 else ''} "
                             f"were made on another dataset ({rec.get('dataset') or 'unnamed'}) than "
                             f"{self.dataset.root}: pass the --data they were made on")
        return []

    def _run_record(self, factory, spec) -> dict:
        """What makes this run's results: Track3D.describe() of a tracker built for the first
        sequence, the restart settings, threads, versions; `frames` is filled per sequence."""
        import datetime

        from ..machine import versions

        track = factory(self.sequences[0])
        desc = track.describe() if hasattr(track, "describe") else {}
        fade = getattr(track, "first_box_fade", None)
        two_d = not getattr(track, "needs_points", True)
        del track
        return {"track3d": desc, "threads": getattr(spec, "threads", None), "restart": self.restart,
                "restart_skip": self.restart_skip, "max_frames": self.max_frames, "split": self.split,
                "dataset": Path(self.dataset.root).resolve().name, "versions": versions(),
                "labels": {seq.name: labels_digest(seq) for seq in self.sequences},
                "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "frames": {},
                # a 2D tracker alone (no 3D box to score): eval's 2D-only or 3D run (_has_3d)
                "two_d": two_d,
                # only when on: the records of runs without it stay as they were
                **({"init_3d": True, "first_box_fade": fade} if self.init_3d else {}),
                # a 2D-only run restarts on the 2D overlap (before, on a 3D IoU it did not have: every
                # other frame); said, so that such a run is never mixed with one of the old rule
                **({"restart_overlap": "2d"} if two_d and self.restart else {}),
                # clouds matched from the pair: the matcher's settings decide them
                **({"stereo": asdict(self.stereo_params or StereoParams())} if self.depth == "stereo" else {})}

    # --- evaluation ----------------------------------------------------------------------------
    def _read_rows(self, name: str, seq: Sequence) -> SequenceResult:
        """The result files of `name` on `seq` as written, cut to the first max_frames frames when
        that is set; refused when they hold more rows than the sequence has frames, or fewer than
        are scored (unless the run record says the run was made over those fewer frames: --frames)."""
        res = read_result(self.folder(name, seq.name), seq.name)
        if len(res) > len(seq):
            raise ValueError(f"{name}/{seq.name}: {len(res)} result rows for a {len(seq)}-frame sequence")
        need = self._frames(seq)
        if len(res) < need:
            rec = read_run_record(self.result_dir, self.split, name) or {}
            if (rec.get("frames") or {}).get(seq.name) != len(res):   # not a recorded --frames run
                raise ValueError(f"{name}/{seq.name}: {len(res)} result rows, the labels have {need} frames"
                                 f"{' (--frames)' if self.max_frames is not None else ''}: every frame needs a "
                                 "row (nan for no output); --frames N scores the first N frames of every run")
        return res if self.max_frames is None else res.head(self.max_frames)

    def _has_3d(self, name: str) -> bool:
        """Whether `name` is a 3D run: some sequence has a 3D box on a frame other than an 'init'
        (decided per run: a sequence of a 3D run without any 3D box has no output, it is not a
        2D-only sequence). An init row holds the ground truth, so a 2D tracker that copies the 3D
        label there and writes nan on every other frame is 2D only (it had been scored AO_3d 0).
        A run record saying whether the loop boxed in 3D (`two_d`, from the loop's own
        needs_points, not the estimator's name: NoEstimator built directly records its class name)
        decides it whatever its rows hold: a loop whose estimator never answered scores AO_3d 0,
        not "2D only"."""
        rec = read_run_record(self.result_dir, self.split, name) or {}
        if isinstance(rec.get("two_d"), bool):
            return not rec["two_d"]
        for seq in self.sequences:
            res = self._read_rows(name, seq)
            if np.isfinite(res.box3d[res.status != INIT]).any():
                return True
        return False

    def missing_3d_files(self, name: str) -> list[str]:
        """The sequences of a 3D run (`_has_3d`) without a ``<seq>_3d_001.txt``: scored as no 3D
        output on any frame (IoU 0), which a misnamed file must not do without a word."""
        if self.own_2d or not self._has_3d(name):
            return []
        return [seq.name for seq in self.sequences if "3d_001" in self._read_rows(name, seq).missing]

    def _run_3d(self, name: str) -> bool:
        """Whether `name` is scored as a 3D run (never when scoring the trackers' own 2D boxes)."""
        return False if self.own_2d else self._has_3d(name)

    def _read(self, name: str, seq: Sequence, run_3d: bool | None = None) -> SequenceResult:
        """The results of `name` on `seq` (_read_rows), checked against the protocol (_check_protocol);
        frames marked skipped have no output (their boxes read as nan: IoU 0, no centre error).
        With own_2d: the 2D tracker's own boxes in place of the reported ones, and no 3D box."""
        res = self._read_rows(name, seq)
        if run_3d is None or self.own_2d:   # the protocol is the run's, whatever is scored of it
            run_3d = self._has_3d(name)
        self._check_protocol(name, seq, res, read_run_record(self.result_dir, self.split, name), run_3d)
        if self.own_2d:
            if "raw_001" in res.missing:
                raise ValueError(f"{name}/{seq.name}: no {seq.name}_raw_001.txt: the 2D tracker's own boxes "
                                 "were not written, there is nothing to score")
            res.box2d = res.box2d_raw.copy()
            res.box3d = np.full_like(res.box3d, np.nan)
        skipped = res.status == SKIPPED
        if skipped.any():
            for k in ("box2d", "box2d_raw", "box3d"):
                a = getattr(res, k).copy()
                a[skipped] = np.nan
                setattr(res, k, a)
        return res

    def _check_protocol(self, name: str, seq: Sequence, res: SequenceResult, rec: dict | None,
                        run_3d: bool) -> None:
        """ValueError naming the sequence and frame when the status file breaks the protocol (results
        of another tracker than run_sequence's, written by hand or by a script): the first frame with the
        target in view is not 'init'; an 'init' with no target, or whose box is not the ground truth's
        (within INIT_TOLERANCE; the 2D box as given or clipped to the image); an 'init' after the
        first in a run whose record says one pass; under restarts, an 'init' that does not follow a
        failure (the last frame with output before it has a present target and overlap <=
        FAILED_OVERLAP) and, when the record says restart_skip, is not the first frame with the
        target in view restart_skip frames after it."""
        st = res.status
        n = len(res)
        where = f"{name}/{seq.name}"
        ok = np.array([_gt_ok(seq, i) for i in range(n)], dtype=bool)
        inits = np.nonzero(st == INIT)[0]
        for j in inits:
            if not ok[j]:
                raise ValueError(f"{where}: frame {j + 1} is 'init' on a frame without the target to start from")
            b3 = res.box3d[j]
            # the raw label or the label clipped to the image: the reader clips a label a few px
            # past the image on a frame flagged cut, and a tracker started from groundtruth_2d.txt
            # reports it unclipped (clipped as the scoring clips a box, it is the reader's label)
            b2 = res.box2d[j]
            ok2 = (np.allclose(b2, seq.gt2d[j], rtol=0, atol=INIT_TOLERANCE[0])
                   or np.allclose(_in_image(b2, seq), seq.gt2d[j], rtol=0, atol=INIT_TOLERANCE[0]))
            ok3 = np.isnan(b3).all() or np.allclose(b3, seq.gt3d[j], rtol=0, atol=INIT_TOLERANCE[1])
            if not (ok2 and ok3):
                def show(a):
                    return "[" + ", ".join(f"{v:.4g}" for v in a) + "]"
                what = (f"its 2D box {show(b2)} is not the label {show(seq.gt2d[j])} (within {INIT_TOLERANCE[0]:g} px)"
                        if not ok2 else
                        f"its 3D box {show(b3)} is not the label {show(seq.gt3d[j])} (within {INIT_TOLERANCE[1]:g} m; "
                        "nan for none)")
                raise ValueError(f"{where}: frame {j + 1} is 'init' but {what}: an initialisation reports the "
                                 "ground truth")
        if not ok.any():
            return
        first = int(np.argmax(ok))
        if st[first] != INIT:
            raise ValueError(f"{where}: frame {first + 1}, the first with the target in view, is {st[first]!r}, "
                             "not 'init' (the tracker starts there from the ground truth; frames before it "
                             "are 'skipped')")
        rec = rec or {}
        later = inits[inits > first]
        if not len(later):
            return
        if rec.get("restart") is False:
            raise ValueError(f"{where}: frame {later[0] + 1} is 'init' but the run record says one pass "
                             "(restart false): no re-initialisation")
        skip = rec.get("restart_skip")
        for j in later:
            k = j - 1
            while k > first and st[k] == SKIPPED:
                k -= 1
            if run_3d:
                overlap = iou_3d(res.box3d[k], seq.gt3d[k])
            elif rec.get("restart") and not rec.get("restart_overlap"):   # the old 2D-only rule: any frame
                overlap = 0.0
            else:
                overlap = iou_2d(_in_image(res.box2d[k], seq), seq.gt2d[k])
            if st[k] == INIT or seq.absent[k] or overlap > FAILED_OVERLAP:
                raise ValueError(f"{where}: frame {j + 1} is 'init' but does not follow a failure (frame {k + 1}, "
                                 f"the last with output before it, has {'no target' if seq.absent[k] else f'overlap {overlap:.3f}'}"
                                 f"{', is an init' if st[k] == INIT else ''}): a restart follows a frame of "
                                 "zero overlap")
            if skip is not None:
                due = k + int(skip)
                expect = due + int(np.argmax(ok[due:])) if due < n and ok[due:].any() else None
                if expect != j:
                    raise ValueError(f"{where}: frame {j + 1} is 'init', but after the failure on frame {k + 1} "
                                     f"the restart (restart_skip {skip}) is due on frame "
                                     f"{'-' if expect is None else expect + 1}")

    def score(self, name: str, raw: bool = False) -> list[SequenceScore]:
        """Scores of one tracker's results against the ground truth, per sequence.

        raw: score the 2D tracker's own boxes (before fusion) instead of the reported ones.
        A run without any 3D box in any sequence (a 2D-only run) is scored in 2D only; in a run
        with 3D boxes a sequence without any scores IoU 0 on each of its scored frames."""
        scores = []
        run_3d = self._run_3d(name)
        for seq in self.sequences:
            res = self._read(name, seq, run_3d)
            if raw and "raw_001" in res.missing:
                raise ValueError(f"{name}/{seq.name}: no {seq.name}_raw_001.txt: the 2D tracker's own boxes "
                                 "were not written, there is nothing to score")
            n = len(res)
            scored = ~seq.absent[:n] & (res.status != INIT)
            timed = res.tracked
            pred3d = res.box3d if run_3d else None
            scores.append(score_sequence(
                seq.name, res.box2d_raw if raw else res.box2d, pred3d, seq.gt2d[:n], seq.gt3d[:n], scored,
                res.restarts,
                tracker_seconds=float(res.seconds[timed].sum()), e2e_seconds=float(res.e2e_seconds[timed].sum()),
                timed_frames=int(timed.sum()), image_size=(seq.camera.width, seq.camera.height)))
        return scores

    def score_conditions(self, name: str) -> dict[str, ConditionScore]:
        """One tracker's scored frames of every sequence pooled by their condition (metrics.CONDITIONS:
        from the ground truth's cut_by_image.label and the depth sensor's range; a sequence whose
        sensor has no range is never past it)."""
        total = {k: ConditionScore() for k in CONDITIONS}
        run_3d = self._run_3d(name)
        for seq in self.sequences:
            res = self._read(name, seq, run_3d)
            n = len(res)
            scored = ~seq.absent[:n] & (res.status != INIT)
            pred3d = res.box3d if run_3d else None
            cond = frame_conditions(seq.gt3d[:n], seq.cut[:n], seq.depth_range_m)
            got = score_conditions(_in_image(res.box2d, seq), pred3d, seq.gt2d[:n], seq.gt3d[:n], scored, cond)
            total = {k: total[k] + got[k] for k in CONDITIONS}
        return total

    def score_lost(self, name: str, reacquire_frames: int = 10) -> LostScore:
        """Lost detection (metrics.score_lost) over every sequence, summed: the frames after each
        sequence's first initialisation (meant for one-pass runs, restart=False)."""
        total = LostScore()
        for seq in self.sequences:
            res = self._read(name, seq)
            inits = np.nonzero(res.status == INIT)[0]
            if not len(inits):
                continue
            sl = slice(int(inits[0]) + 1, len(res))
            total = total + score_lost(res.status[sl] == LOST, seq.absent[sl], _in_image(res.box2d[sl], seq), seq.gt2d[sl],
                                       reacquire_frames)
        return total

    def stage_ms(self, name: str) -> np.ndarray:
        """(frames, len(STAGES)) milliseconds of every tracked (timed) frame of all sequences."""
        rows = []
        for seq in self.sequences:
            res = self._read(name, seq)
            rows.append(res.stage_ms[res.tracked])
        return np.concatenate(rows) if rows else np.zeros((0, len(STAGES)))

    def report(self, names: list[str], plots: bool = True, trajectories: int = 4, worst_first: bool = True,
               baseline: str | None = None) -> dict:
        """Scores, report.json and plots (success/precision curves, AO per sequence, 3D trajectories
        of `trajectories` sequences: the worst ones, lowest mean AO over the runs, unless
        `worst_first` is False, then the first ones) in report_dir.
        Each tracker's "lost" holds how its status "lost" matched the absent frames (score_lost:
        from each sequence's first initialisation on; precision / recall also in "overall");
        its "intervals" the bootstrap intervals of its means over sequences (INTERVAL_METRICS,
        metrics.bootstrap_interval). "paired": every other run against `baseline` (default: the
        first of `names`), sequence by sequence (metrics.compare_paired)."""
        if baseline is not None and baseline not in names:
            raise ValueError(f"baseline {baseline!r} is not one of the compared runs: {', '.join(names)}")
        self.report_dir.mkdir(parents=True, exist_ok=True)
        report: dict = {
            "dataset": str(self.dataset.root), "split": self.split, "sequences": [s.name for s in self.sequences],
            "max_frames": self.max_frames, "restart": self.restart, "restart_skip": self.restart_skip,
            # which boxes were scored: the loop's reported ones, or the 2D trackers' own (own_2d)
            **({"boxes": "tracker's own 2D"} if self.own_2d else {}),
            "cpu": cpu_name(), "thresholds": {"iou": IOU_THRESHOLDS, "ce_2d_px": CE2D_THRESHOLDS,
                                              "ce_3d_m": CE3D_THRESHOLDS},
            "trackers": {},
        }
        overall = {}
        runs = {n: read_run_record(self.result_dir, self.split, n) for n in names}
        label_warnings = [w for n in names for w in self.check_labels(n)]
        lengths = {}
        per_sequence = {}
        for name in names:
            scores = self.score(name)
            per_sequence[name] = scores
            ov = average_scores(scores)
            overall[name] = ov
            lengths[name] = {seq.name: len(self._read(name, seq)) for seq in self.sequences}
            rec = runs[name] or {}
            lost = self.score_lost(name).summary()
            report["trackers"][name] = {
                "overall": {**ov.summary(), "lost_precision": lost["lost_precision"],
                            "lost_recall": lost["lost_recall"], "result_frames": sum(lengths[name].values()),
                            **latency_ms(self.stage_ms(name)[:, STAGES.index("total")])},
                "lost": lost,
                "curves": ov.curves,
                "sequences": {s.name: s.summary() for s in scores},
                "conditions": self._condition_summary(name, ov),
                "stage_ms_mean": self._stage_means(name),
                "run": rec or None,
                "restart": rec.get("restart"), "restart_skip": rec.get("restart_skip"),
            }
        values = {n: {k: {sc.name: getattr(sc, k) for sc in per_sequence[n] if sc.frames > 0} for k in INTERVAL_METRICS}
                  for n in names}
        for name in names:
            report["trackers"][name]["intervals"] = {k: list(bootstrap_interval(list(values[name][k].values())))
                                                     for k in INTERVAL_METRICS}
        base = baseline if baseline is not None else names[0]
        report["paired"] = {"baseline": base, "level": CI_LEVEL, "margin": MOVED,
                            "trackers": {n: {k: compare_paired(k, values[base][k], values[n][k]).summary()
                                             for k in INTERVAL_METRICS} for n in names if n != base}}
        # a run with nothing scored reads as a row of dashes: say why
        empty = [f"{n}: no frame to score (a scored frame is a present target's after the initialisation, "
                 f"and every result frame here is an initialisation or an absent target's)"
                 for n in names if overall[n].frames == 0]
        # results shorter than the frames scored (a run made with --frames N, evaluated without)
        # are scored on what they hold: say so, the report's max_frames says nothing of it
        short = []
        for n in names:
            cut = [s.name for s in self.sequences if lengths[n][s.name] < self._frames(s)]
            if cut:
                made = (runs[n] or {}).get("max_frames")
                how = f" (the run was made with --frames {made})" if made else ""
                short.append(f"{n}: {len(cut)} of {len(self.sequences)} sequences hold fewer result frames than "
                             f"are scored{how}: scored on the frames they hold; pass --frames to score the same "
                             f"frames of every run")
        # a sequence without a box on any scored frame leaves ACE undefined: name them
        no_centre = []
        for n in names:
            for k, what in (("ace_2d", "2D"), ("ace_3d", "3D")):
                if k == "ace_3d" and overall[n].two_d_only:
                    continue
                seqs = [sc.name for sc in per_sequence[n] if sc.frames > 0 and not np.isfinite(getattr(sc, k))]
                if seqs:
                    no_centre.append(f"{n}: {k.upper()} undefined: {len(seqs)} sequence(s) without a {what} box on "
                                     f"any scored frame ({', '.join(seqs[:4])}{', ...' if len(seqs) > 4 else ''})")
        no_3d_file = []
        for n in names:
            seqs = self.missing_3d_files(n)
            if seqs:
                no_3d_file.append(f"{n}: a 3D run, but {len(seqs)} sequence(s) have no <seq>_3d_001.txt "
                                  f"({', '.join(seqs[:4])}{', ...' if len(seqs) > 4 else ''}): scored as no 3D "
                                  "output (IoU 0) on every frame")
        report["warnings"] = (label_warnings + _comparison_warnings(names, runs, lengths) + empty + short
                              + no_3d_file + no_centre)
        known = [(r.get("restart"), r.get("restart_skip")) for r in runs.values() if r]
        if known and len(set(known)) == 1 and len(known) == len(names) and None not in known[0]:
            report["restart"], report["restart_skip"] = known[0]
        else:   # unknown (results without a record) or mixed: say so, never a made-up value
            report["restart"] = report["restart_skip"] = None
        # only once every run scored: an eval refused on a bad file keeps the previous report
        self._remove_old_plots()
        if plots:
            from . import plots as P

            files = P.curve_plots(overall, self.report_dir, own_2d=self.own_2d)
            files.append(P.sequence_plot(per_sequence, self.report_dir))
            axes = P.axis_error_plot(overall, self.report_dir)
            if axes is not None:
                files.append(axes)
            where = P.condition_plot({n: report["trackers"][n]["conditions"] for n in names}, self.report_dir)
            if where is not None:
                files.append(where)
            seq_names = P.worst_sequences(per_sequence, trajectories) if worst_first else \
                [s.name for s in self.sequences[:trajectories]]
            files += P.trajectory_plots(self, names, seq_names, self.report_dir)
            report["plots"] = [str(f) for f in files]
        write_json(self.report_dir / "report.json", report)
        return report

    def _condition_summary(self, name: str, ov: OverallScore) -> dict:
        """report.json's "conditions" of one tracker: metrics.ConditionScore.summary of each."""
        cond = self.score_conditions(name)
        total = sum(c.frames for c in cond.values())
        return {k: c.summary(total, ov.two_d_only) for k, c in cond.items()}

    def _remove_old_plots(self) -> None:
        """The plots a previous report in report_dir listed, and that report itself: a report of
        fewer sequences or without plots must not sit beside them, and an evaluation killed while
        it drew must not leave the old report.json beside its new plots. Only files that report
        named, by name inside report_dir (a report folder copied or moved elsewhere lists paths
        of where it was: its plots had stayed)."""
        old = self.report_dir / "report.json"
        try:
            files = json.loads(old.read_text()).get("plots") or []
        except (OSError, ValueError, AttributeError):
            return
        for f in files:
            p = self.report_dir / Path(str(f)).name
            if p.suffix.lower() in (".png", ".pdf", ".svg") and p.is_file():
                p.unlink()
        for stale in (old, self.report_dir / "sequences.txt"):   # written again at the end
            stale.unlink(missing_ok=True)

    def _stage_means(self, name: str) -> dict:
        a = self.stage_ms(name)
        return {k: float(a[:, j].mean()) if len(a) else float("nan") for j, k in enumerate(STAGES)}


def evaluate_2d(root: str | Path, split: str, specs: list[TrackerSpec], result_dir: str | Path | None = None,
                max_sequences: int | None = None, reacquire_frames: int = 10, quiet: bool = True) -> dict[str, dict]:
    """One-pass 2D evaluation (restart=False, estimator "none") of 2D trackers on a split:
    {label: overall summary (metrics.OverallScore.summary) + the median tracker ms per frame
    (``ms_median``) + lost detection (metrics.LostScore.summary)}. The training CLIs' ``eval``
    use it; result files go to `result_dir` (default: a temporary folder, removed)."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(result_dir) if result_dir is not None else Path(tmp)
        exp = Experiment(root, split, folder / "results", folder / "report", restart=False,
                         max_sequences=max_sequences)
        out = {}
        for spec in specs:
            if spec.estimator != "none":
                raise ValueError(f"evaluate_2d runs 2D trackers alone (estimator 'none'), got {spec.estimator!r}")
            exp.run(spec, quiet=quiet)
            total_ms = exp.stage_ms(spec.label)[:, STAGES.index("total")]
            out[spec.label] = {**average_scores(exp.score(spec.label)).summary(),
                               "ms_median": latency_ms(total_ms)["ms_median"],
                               **exp.score_lost(spec.label, reacquire_frames).summary()}
        return out
