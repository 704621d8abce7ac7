"""The training recipes of the shipped models, named in one place, each with a tiny variant.

A recipe is the whole path from nothing to an ONNX file: simulate the data, cut the caches,
train (one thread, resumable, under a time budget), export with a parity check, and for
EdgeTrack fit the lost threshold. Each step is one call of the project's own CLIs; every
step resumes (the simulator from its last complete sequence, the trainings from their last
checkpoint, the caches are skipped when present), so running a recipe again after an
interruption continues where it stopped.

    track3d-train recipe list
    track3d-train recipe show a3boxnet-engine          # the commands, full size
    track3d-train recipe run a3boxnet-engine --data data --runs runs
    track3d-train recipe run edgetrack-engine --tiny --data tiny/data --runs tiny/runs   # a minute, CI

The models land in the run folder (``{runs}/<recipe>/...``), never in the package: a model
ships only after it beats the shipped one on the README's engine sets, by
``track3d-train <model> export --force`` into ``runtime/track3d/models``.

Knobs (``--set name=value``) scale a recipe; ``tiny`` overrides them so that the whole recipe
runs in about a minute on tiny data (CI runs it end to end); tiny-only differences are the
knobs, never the commands.
"""
from __future__ import annotations

import shlex
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

__all__ = ["Step", "Recipe", "RECIPES", "recipe", "commands", "run", "build_parser", "main"]


@dataclass(frozen=True)
class Step:
    """One command. ``argv``: the program ("track3d-sim" | "track3d-train") and its arguments,
    with ``{data}``, ``{runs}`` and knob placeholders; ``done_when``: a path whose existence
    means the step has nothing left to do (skipped); ``full_only``: not run by the tiny variant
    (it needs data the tiny variant does not have, said in ``why``)."""

    label: str
    argv: tuple[str, ...]
    done_when: str | None = None
    full_only: bool = False
    why: str = ""


@dataclass(frozen=True)
class Recipe:
    name: str
    makes: str
    description: str
    knobs: dict
    tiny: dict
    steps: tuple[Step, ...]
    notes: tuple[str, ...] = field(default_factory=tuple)


# The exports pass --force: a recipe run again exports again over its own earlier export (an
# export refuses to overwrite a file that exists without it); the models land under {runs}.
def _a(text: str) -> tuple[str, ...]:
    return tuple(shlex.split(text))


_BOXNET_TRAIN = ("track3d-train boxnet train --cache {runs}/boxnet-engine/cache/engine-train-po.npz "
                 "{runs}/boxnet-engine/cache/engine-train-stereo.npz --num-points 512 --epochs 100 "
                 "--epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} --flip-y --scale-aug 0.15 --no-category "
                 "--threads {threads} --quiet ")

# The points-only bodies and their frustum caches, shared by a3boxnet-engine and a3boxnet-narrow
# (the same paths, so that one recipe finds the other's data done).
_PO_DATA = Step("data: points-only bodies, range sensors mixed", _a(
    "track3d-sim generate --preset {preset} --seed 1 --train {po_train} --test 0 --test-unseen 1 "
    "--frames {frames} --points-only --sensors ideal,flash-lidar,tof --out {data}/engine-train-po "
    "--workers {workers} --quiet"))
_PO2_DATA = Step("data: more points-only bodies (another seed)", _a(
    "track3d-sim generate --preset {preset} --seed 5 --train {po2_train} --test 0 --test-unseen 1 "
    "--frames {frames} --points-only --sensors ideal,flash-lidar,tof --out {data}/engine-train-po2 "
    "--workers {workers} --quiet"))
_PO_CACHE = Step("cache: frustums of jittered ground-truth boxes (points-only)", _a(
    "track3d-train boxnet prepare --data {data}/engine-train-po --split train --jitters {jitters} "
    "--out {runs}/boxnet-engine/cache/engine-train-po.npz --quiet"),
    done_when="{runs}/boxnet-engine/cache/engine-train-po.npz")
_PO2_CACHE = Step("cache: frustums (more points-only bodies)", _a(
    "track3d-train boxnet prepare --data {data}/engine-train-po2 --split train --jitters {jitters} "
    "--out {runs}/boxnet-engine/cache/engine-train-po2.npz --quiet"),
    done_when="{runs}/boxnet-engine/cache/engine-train-po2.npz")

A3BOXNET_ENGINE = Recipe(
    name="a3boxnet-engine",
    makes="{runs}/boxnet-engine/a3boxnet.onnx",
    description="A3BoxNet on the data engine: points-only bodies of every generator but the held-out ones, "
                "every range sensor, plus stereo bodies; no category input; three phases (extent coding, "
                "then a per-axis stretch augmentation, then a fine-tune with 360 more points-only bodies).",
    knobs={"preset": "small", "po_train": 240, "po2_train": 360, "stereo_train": 36, "frames": 25, "jitters": 3,
           "epoch_samples": 4000, "batch": 32, "max_steps": 0, "minutes": 105, "stretch_minutes": 40,
           "more_minutes": 70, "threads": 1, "workers": 1},
    tiny={"preset": "tiny", "po_train": 2, "po2_train": 2, "stereo_train": 1, "frames": 4, "jitters": 1,
          "epoch_samples": 16, "batch": 8,
          "max_steps": 2, "minutes": 5, "stretch_minutes": 5, "more_minutes": 5},
    steps=(
        _PO_DATA,
        Step("data: stereo bodies (images for the stereo matcher)", _a(
            "track3d-sim generate --preset {preset} --seed 2 --train {stereo_train} --test 0 --test-unseen 1 "
            "--frames {frames} --sensors stereo --out {data}/engine-train-stereo --workers {workers} --quiet")),
        _PO2_DATA, _PO_CACHE, _PO2_CACHE,
        Step("cache: frustums (stereo)", _a(
            "track3d-train boxnet prepare --data {data}/engine-train-stereo --split train --jitters {jitters} "
            "--out {runs}/boxnet-engine/cache/engine-train-stereo.npz --quiet"),
            done_when="{runs}/boxnet-engine/cache/engine-train-stereo.npz"),
        Step("train phase 1: extent coding", _a(
            _BOXNET_TRAIN + "--out {runs}/boxnet-engine/nocat --time-budget-min {minutes} --size-norm extent")),
        Step("train phase 2: + stretch augmentation, from phase 1", _a(
            _BOXNET_TRAIN + "--out {runs}/boxnet-engine/stretch --time-budget-min {stretch_minutes} "
            "--stretch-aug 0.3 --size-norm extent --lr 5e-4 --init-from {runs}/boxnet-engine/nocat/best.pt")),
        Step("train phase 3: the same on 1.5x more bodies, from phase 2", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-engine/cache/engine-train-po.npz "
            "{runs}/boxnet-engine/cache/engine-train-po2.npz {runs}/boxnet-engine/cache/engine-train-stereo.npz "
            "--num-points 512 --epochs 100 --epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} "
            "--flip-y --scale-aug 0.15 --no-category --threads {threads} --quiet "
            "--out {runs}/boxnet-engine/more --time-budget-min {more_minutes} --stretch-aug 0.3 --size-norm extent "
            "--lr 3e-4 --init-from {runs}/boxnet-engine/stretch/best.pt")),
        Step("export with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-engine/more/best.pt "
            "--out {runs}/boxnet-engine/a3boxnet.onnx")),
    ),
    notes=("The shipped phase 2 started from phase 1's best checkpoint at epoch 51, copied while phase 1 ran "
           "(105 min budget, 65 min in); run as written, phase 2 starts from phase 1's final best.",
           "The shipped phase 3 ran 79 epochs in its 70 minutes on one thread (best by validation AO_3d).",),
)

EDGETRACK_ENGINE = Recipe(
    name="edgetrack-engine",
    makes="{runs}/edgetrack/model/edgetrack_{{template,search}}.onnx",
    description="EdgeTrack, the default 2D tracker: 36 train sequences x 100 frames plus 120 shapes x 25 frames "
                "in low light with motion blur; ~70 min on one thread, then ~22 min fine-tuning with a distinct "
                "colour outside the image and crops cut at a simulated image border; the motion weight and the "
                "lost threshold fitted on 36 held-out train-like sequences (seeds 3, 4).",
    knobs={"preset": "small", "train": 36, "div_train": 120, "div_frames": 25, "max_frames": 3600,
           "max_background": 1500, "steps": 30000, "batch": 32, "minutes": 70, "pad_steps": 4000,
           "border_cut": 0.3, "motion": "1", "threads": 1, "workers": 2},
    tiny={"preset": "tiny", "train": 2, "div_train": 1, "div_frames": 4, "max_frames": 40, "max_background": 10,
          "steps": 2, "batch": 4, "minutes": 5, "pad_steps": 3, "workers": 1},
    steps=(
        Step("data: train sequences", _a(
            "track3d-sim generate --preset {preset} --train {train} --test 0 --test-unseen 1 "
            "--out {data}/engine-train --workers {workers} --quiet")),
        Step("data: more shapes, low light, motion blur", _a(
            "track3d-sim generate --preset {preset} --seed 1 --train {div_train} --test 0 --test-unseen 1 "
            "--frames {div_frames} --auto-exposure --motion-blur --out {data}/engine-train_div --workers {workers} "
            "--quiet")),
        Step("cache: target and background crops, the frame's mean colour outside the image", _a(
            "track3d-train edgetrack prepare --data {data}/engine-train {data}/engine-train_div "
            "--max-frames {max_frames} --max-background {max_background} --pad mean --out {runs}/edgetrack/cache "
            "--quiet"), done_when="{runs}/edgetrack/cache/background/bg.json"),
        Step("train", _a(
            "track3d-train edgetrack train --cache {runs}/edgetrack/cache --out {runs}/edgetrack/run "
            "--max-steps {steps} --batch {batch} --time-budget-min {minutes} --threads {threads} --quiet")),
        Step("cache: the same crops, magenta outside the image", _a(
            "track3d-train edgetrack prepare --data {data}/engine-train {data}/engine-train_div "
            "--max-frames {max_frames} --max-background {max_background} --out {runs}/edgetrack/cache-pad --quiet"),
            done_when="{runs}/edgetrack/cache-pad/background/bg.json"),
        Step("fine-tune on it with border cuts, from the first training", _a(
            "track3d-train edgetrack train --cache {runs}/edgetrack/cache-pad --out {runs}/edgetrack/pad "
            "--init-from {runs}/edgetrack/run/ckpt.pt --border-cut {border_cut} --lr 1e-3 --max-steps {pad_steps} "
            "--batch {batch} --threads {threads} --quiet")),
        Step("export with a parity check", _a(
            "track3d-train edgetrack export --force --checkpoint {runs}/edgetrack/pad/ckpt.pt "
            "--out {runs}/edgetrack/model/edgetrack")),
        Step("data: held-out sequences for the lost threshold", _a(
            "track3d-sim generate --preset small --seed 3 --train 12 --test 0 --test-unseen 1 --frames 60 "
            "--sensors ideal --out {data}/engine-calib --workers {workers} --quiet"),
            full_only=True, why="the tiny presets' sequences have no absent frames to fit on"),
        Step("data: more held-out sequences", _a(
            "track3d-sim generate --preset small --seed 4 --train 24 --test 0 --test-unseen 1 --frames 60 "
            "--sensors ideal --out {data}/engine-calib2 --workers {workers} --quiet"), full_only=True,
            why="twelve sequences alone decide the motion weight by noise"),
        Step("fit the motion weight and the lost threshold", _a(
            "track3d-train edgetrack fit-threshold --model {runs}/edgetrack/model/edgetrack "
            "--data {data}/engine-calib {data}/engine-calib2 --split train --motion-grid {motion} --write --quiet"),
            full_only=True, why="needs the held-out sequences above"),
    ),
    notes=("The motion weight: the 2D grid 0,0.5,1,1.5 (`--set motion=0,0.5,1,1.5`) picks 1.5 over 1 by 0.001 AO_2d "
           "on seeds 3 + 4; in the 3D loop on seeds 3, 4 and 7 (60 held-out sequences, one pass) 1 scored AO_3d "
           "0.8858 against 0.8844 and the lost flag precision / recall 0.84 / 0.94 against 0.84 / 0.92, so the "
           "shipped pair has 1.",),
)

SIAMFC = Recipe(
    name="siamfc",
    makes="{runs}/siamfc_{{edge,faithful}}/model_{{exemplar,search}}.onnx",
    description="The paper's SiamFC (faithful) and our SiamFC-edge, on the first release's data "
                "(36 train + 18 test sequences x 100 frames, data/med).",
    knobs={"preset": "small", "train": 36, "test": 18, "max_frames": 3600, "edge_steps": 4800, "edge_minutes": 36,
           "faithful_steps": 900, "faithful_minutes": 40, "workers": 2},
    tiny={"preset": "tiny", "train": 2, "test": 1, "max_frames": 20, "edge_steps": 1, "edge_minutes": 5,
          "faithful_steps": 1, "faithful_minutes": 5, "workers": 1},
    steps=(
        Step("data", _a("track3d-sim generate --preset {preset} --train {train} --test {test} --out {data}/med "
                        "--workers {workers} --quiet")),
        Step("cache: training pairs", _a(
            "track3d-train siamfc prepare --data {data}/med --split train --max-frames {max_frames} "
            "--out {runs}/siamfc/cache --quiet"), done_when="{runs}/siamfc/cache/index.json"),
        Step("train SiamFC-edge", _a(
            "track3d-train siamfc train --variant edge --cache {runs}/siamfc/cache --out {runs}/siamfc_edge "
            "--max-steps {edge_steps} --batch 16 --time-budget-min {edge_minutes} --threads 1 --quiet")),
        Step("train SiamFC (faithful)", _a(
            "track3d-train siamfc train --variant faithful --cache {runs}/siamfc/cache --out {runs}/siamfc_faithful "
            "--max-steps {faithful_steps} --batch 8 --time-budget-min {faithful_minutes} --threads 2 --quiet")),
        Step("export SiamFC-edge", _a(
            "track3d-train siamfc export --force --checkpoint {runs}/siamfc_edge/ckpt.pt --out {runs}/siamfc_edge/model")),
        Step("export SiamFC (faithful)", _a(
            "track3d-train siamfc export --force --checkpoint {runs}/siamfc_faithful/ckpt.pt "
            "--out {runs}/siamfc_faithful/model")),
    ),
)

A3BOXNET_STEREO = Recipe(
    name="a3boxnet-stereo",
    makes="{runs}/boxnet-stereo/a3boxnet_stereo.onnx",
    description="A3BoxNet for block-matching stereo depth (track3d.boxnet.SENSOR_MODELS): the shipped A3BoxNet "
                "fine-tuned on stereo bodies only, 180 sequences x 25 frames of every generator but the held-out "
                "ones (two seeds), depth from track3d.stereo; ~45 min on one thread.",
    knobs={"preset": "small", "train_a": 120, "train_b": 60, "frames": 25, "jitters": 3, "epoch_samples": 4000,
           "batch": 32, "max_steps": 0, "minutes": 45, "threads": 1, "workers": 1, "parent": "a3boxnet.onnx"},
    tiny={"preset": "tiny", "train_a": 1, "train_b": 1, "frames": 4, "jitters": 1, "epoch_samples": 16, "batch": 8,
          "max_steps": 2, "minutes": 5},
    steps=(
        Step("data: stereo bodies (seed 2)", _a(
            "track3d-sim generate --preset {preset} --seed 2 --train {train_a} --test 0 --test-unseen 1 "
            "--frames {frames} --sensors stereo --out {data}/stereo-train-s2 --workers {workers} --quiet")),
        Step("data: stereo bodies (seed 12)", _a(
            "track3d-sim generate --preset {preset} --seed 12 --train {train_b} --test 0 --test-unseen 1 "
            "--frames {frames} --sensors stereo --out {data}/stereo-train-s12 --workers {workers} --quiet")),
        Step("cache: frustums of jittered ground-truth boxes (seed 2)", _a(
            "track3d-train boxnet prepare --data {data}/stereo-train-s2 --split train --jitters {jitters} "
            "--out {runs}/boxnet-stereo/cache/stereo-train-s2.npz --quiet"),
            done_when="{runs}/boxnet-stereo/cache/stereo-train-s2.npz"),
        Step("cache: frustums (seed 12)", _a(
            "track3d-train boxnet prepare --data {data}/stereo-train-s12 --split train --jitters {jitters} "
            "--out {runs}/boxnet-stereo/cache/stereo-train-s12.npz --quiet"),
            done_when="{runs}/boxnet-stereo/cache/stereo-train-s12.npz"),
        Step("train: fine-tune the shipped model (its ONNX) on the stereo bodies", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-stereo/cache/stereo-train-s2.npz "
            "{runs}/boxnet-stereo/cache/stereo-train-s12.npz --num-points 512 --epochs 100 "
            "--epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} --flip-y --scale-aug 0.15 "
            "--no-category --threads {threads} --quiet --out {runs}/boxnet-stereo/run --time-budget-min {minutes} "
            "--stretch-aug 0.3 --size-norm extent --lr 3e-4 --init-from {parent}")),
        Step("export with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-stereo/run/best.pt "
            "--out {runs}/boxnet-stereo/a3boxnet_stereo.onnx --depth-sensor stereo")),
    ),
    notes=("`parent` is the shipped a3boxnet.onnx by name (or any A3BoxNet .onnx / checkpoint path).",),
)

A3BOXNET_STEREO_NARROW = Recipe(
    name="a3boxnet-stereo-narrow",
    makes="{runs}/boxnet-stereo-narrow/a3boxnet_stereo_narrow.onnx",
    description="The stereo A3BoxNet at half width: the shipped stereo model (a3boxnet_stereo.onnx, recipe "
                "a3boxnet-stereo) cut to half width and fine-tuned on the stereo recipe's bodies to fit both "
                "the ground truth and the stereo model's outputs (distillation, ~45 min on one thread).",
    knobs={"preset": "small", "train_a": 120, "train_b": 60, "frames": 25, "jitters": 3, "epoch_samples": 4000,
           "batch": 32, "max_steps": 0, "minutes": 45, "threads": 1, "workers": 1, "width": 0.5,
           "teacher": "a3boxnet_stereo.onnx", "distill_weight": 1.0},
    tiny={"preset": "tiny", "train_a": 1, "train_b": 1, "frames": 4, "jitters": 1, "epoch_samples": 16, "batch": 8,
          "max_steps": 2, "minutes": 5},
    steps=A3BOXNET_STEREO.steps[:4] + (
        Step("train: cut the stereo model to the width, fine-tune on ground truth + its outputs", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-stereo/cache/stereo-train-s2.npz "
            "{runs}/boxnet-stereo/cache/stereo-train-s12.npz --num-points 512 --epochs 100 "
            "--epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} --flip-y --scale-aug 0.15 "
            "--no-category --threads {threads} --quiet --out {runs}/boxnet-stereo-narrow/run "
            "--time-budget-min {minutes} --stretch-aug 0.3 --size-norm extent --lr 3e-4 --width {width} "
            "--init-from {teacher} --distill-from {teacher} --distill-weight {distill_weight}")),
        Step("export with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-stereo-narrow/run/best.pt "
            "--out {runs}/boxnet-stereo-narrow/a3boxnet_stereo_narrow.onnx --depth-sensor stereo")),
    ),
    notes=("The data and caches are the a3boxnet-stereo recipe's (made once for both).",
           "`teacher` is the shipped a3boxnet_stereo.onnx by name (or any A3BoxNet .onnx / checkpoint path, e.g. "
           "{runs}/boxnet-stereo/a3boxnet_stereo.onnx after the a3boxnet-stereo recipe).",),
)

A3BOXNET_STEREO_BACKLIT = Recipe(
    name="a3boxnet-stereo-backlit",
    makes="{runs}/boxnet-stereo-backlit/a3boxnet_stereo_backlit.onnx",
    description="A3BoxNet for block-matching stereo depth of bodies lit from behind (track3d.boxnet.BACKLIT_MODELS, "
                "run past 100 degrees of phase when the sun is known): the shipped stereo model fine-tuned on "
                "crescents only, 138 sequences x 50 frames of every generator but the held-out ones lit at "
                "90-160 degrees of phase (three seeds); ~40 min on one thread.",
    knobs={"preset": "small", "train_a": 48, "train_b": 60, "train_c": 30, "frames": 50, "phase": "90:160",
           "jitters": 3, "epoch_samples": 4000, "batch": 32, "max_steps": 0, "epochs": 40, "minutes": 40,
           "lr": 1.5e-4, "threads": 1, "workers": 1, "parent": "a3boxnet_stereo.onnx"},
    tiny={"preset": "tiny", "train_a": 1, "train_b": 1, "train_c": 1, "frames": 4, "jitters": 1, "epoch_samples": 16,
          "batch": 8, "max_steps": 2, "epochs": 1, "minutes": 5},
    steps=tuple(
        s for seed, n in (("11", "a"), ("13", "b"), ("14", "c")) for s in (
            Step(f"data: stereo bodies lit from behind (seed {seed})", _a(
                f"track3d-sim generate --preset {{preset}} --seed {seed} --train {{train_{n}}} --test 0 "
                f"--test-unseen 1 --frames {{frames}} --sun-phase {{phase}} --sensors stereo "
                f"--out {{data}}/stereo-backlit-s{seed} --workers {{workers}} --quiet")),
            Step(f"cache: frustums of jittered ground-truth boxes (seed {seed})", _a(
                f"track3d-train boxnet prepare --data {{data}}/stereo-backlit-s{seed} --split train "
                f"--jitters {{jitters}} --out {{runs}}/boxnet-stereo-backlit/cache/stereo-backlit-s{seed}.npz --quiet"),
                done_when=f"{{runs}}/boxnet-stereo-backlit/cache/stereo-backlit-s{seed}.npz"))
    ) + (
        Step("train: fine-tune the shipped stereo model (its ONNX) on the crescents", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-stereo-backlit/cache/stereo-backlit-s11.npz "
            "{runs}/boxnet-stereo-backlit/cache/stereo-backlit-s13.npz "
            "{runs}/boxnet-stereo-backlit/cache/stereo-backlit-s14.npz --num-points 512 --epochs {epochs} "
            "--epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} --flip-y --scale-aug 0.15 "
            "--no-category --threads {threads} --quiet --out {runs}/boxnet-stereo-backlit/run "
            "--time-budget-min {minutes} --stretch-aug 0.3 --size-norm extent --lr {lr} --init-from {parent}")),
        Step("export with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-stereo-backlit/run/best.pt "
            "--out {runs}/boxnet-stereo-backlit/a3boxnet_stereo_backlit.onnx --depth-sensor stereo")),
    ),
    notes=("`parent` is the shipped a3boxnet_stereo.onnx by name (recipe a3boxnet-stereo; or any A3BoxNet .onnx / "
           "checkpoint path).",
           "The training picks the epoch of the best validation AO_3d (best.pt); the validation sequences are "
           "every 8th of the caches'.",),
)

A3BOXNET_NARROW = Recipe(
    name="a3boxnet-narrow",
    makes="{runs}/boxnet-narrow/a3boxnet_narrow.onnx",
    description="The single-frame A3BoxNet (the paper's variant; the default model is a3boxnet-views, made from it): the full-width model (a3boxnet.onnx, recipe a3boxnet-engine) cut to half "
                "width (the channels that matter most to the next layer kept) and fine-tuned on the data engine's "
                "points-only bodies to fit both the ground truth and the full-width model's outputs "
                "(distillation, ~45 min on one thread); then fine-tuned again, still distilled, with superquadric "
                "bodies added to the training world (~100 min); then once more with Gaussian random spheres "
                "added (~75 min); then its int8 twin.",
    knobs={"preset": "small", "po_train": 240, "po2_train": 360, "sq_train": 240, "gs_train": 240, "frames": 25,
           "jitters": 3, "epoch_samples": 4000, "batch": 32, "max_steps": 0, "minutes": 45, "sq_minutes": 100,
           "gs_minutes": 75, "threads": 1, "workers": 1, "width": 0.5, "teacher": "a3boxnet.onnx",
           "distill_weight": 1.0},
    tiny={"preset": "tiny", "po_train": 2, "po2_train": 2, "sq_train": 2, "gs_train": 2, "frames": 4, "jitters": 1,
          "epoch_samples": 16, "batch": 8, "max_steps": 2, "minutes": 5, "sq_minutes": 5, "gs_minutes": 5},
    steps=(
        _PO_DATA, _PO2_DATA,
        Step("data: superquadric bodies (boxy to pinched, any flattening), range sensors mixed", _a(
            "track3d-sim generate --preset {preset} --seed 21 --train {sq_train} --test 0 --test-unseen 1 "
            "--frames {frames} --points-only --sensors ideal,flash-lidar,tof --generators superquadric "
            "--out {data}/engine-train-sq --workers {workers} --quiet")),
        Step("data: Gaussian random spheres (lumps and hollows of every size), range sensors mixed", _a(
            "track3d-sim generate --preset {preset} --seed 31 --train {gs_train} --test 0 --test-unseen 1 "
            "--frames {frames} --points-only --sensors ideal,flash-lidar,tof --generators gaussian_sphere "
            "--out {data}/engine-train-gs --workers {workers} --quiet")),
        _PO_CACHE, _PO2_CACHE,
        Step("cache: frustums (superquadric bodies)", _a(
            "track3d-train boxnet prepare --data {data}/engine-train-sq --split train --jitters {jitters} "
            "--out {runs}/boxnet-engine/cache/engine-train-sq.npz --quiet"),
            done_when="{runs}/boxnet-engine/cache/engine-train-sq.npz"),
        Step("cache: frustums (Gaussian random spheres)", _a(
            "track3d-train boxnet prepare --data {data}/engine-train-gs --split train --jitters {jitters} "
            "--out {runs}/boxnet-engine/cache/engine-train-gs.npz --quiet"),
            done_when="{runs}/boxnet-engine/cache/engine-train-gs.npz"),
        Step("train stage 1: cut the teacher to the width, fine-tune on ground truth + the teacher's outputs", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-engine/cache/engine-train-po.npz "
            "{runs}/boxnet-engine/cache/engine-train-po2.npz --num-points 512 --epochs 100 "
            "--epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} --flip-y --scale-aug 0.15 "
            "--no-category --threads {threads} --quiet --out {runs}/boxnet-narrow/run --time-budget-min {minutes} "
            "--stretch-aug 0.3 --size-norm extent --lr 3e-4 --width {width} --init-from {teacher} "
            "--distill-from {teacher} --distill-weight {distill_weight}")),
        Step("export stage 1 with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-narrow/run/best.pt "
            "--out {runs}/boxnet-narrow/stage1/a3boxnet_narrow.onnx")),
        Step("train stage 2: stage 1 fine-tuned with the superquadric bodies added, still distilled", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-engine/cache/engine-train-po.npz "
            "{runs}/boxnet-engine/cache/engine-train-po2.npz {runs}/boxnet-engine/cache/engine-train-sq.npz "
            "--num-points 512 --epochs 200 --epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} "
            "--flip-y --scale-aug 0.15 --no-category --threads {threads} --quiet --out {runs}/boxnet-narrow/sq "
            "--time-budget-min {sq_minutes} --stretch-aug 0.3 --size-norm extent --lr 3e-4 --width {width} "
            "--init-from {runs}/boxnet-narrow/stage1/a3boxnet_narrow.onnx "
            "--distill-from {teacher} --distill-weight {distill_weight}")),
        Step("export stage 2 with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-narrow/sq/best.pt "
            "--out {runs}/boxnet-narrow/stage2/a3boxnet_narrow.onnx")),
        Step("train stage 3: stage 2 fine-tuned with the Gaussian random spheres added, still distilled", _a(
            "track3d-train boxnet train --cache {runs}/boxnet-engine/cache/engine-train-po.npz "
            "{runs}/boxnet-engine/cache/engine-train-po2.npz {runs}/boxnet-engine/cache/engine-train-sq.npz "
            "{runs}/boxnet-engine/cache/engine-train-gs.npz "
            "--num-points 512 --epochs 200 --epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} "
            "--flip-y --scale-aug 0.15 --no-category --threads {threads} --quiet --out {runs}/boxnet-narrow/gs "
            "--time-budget-min {gs_minutes} --stretch-aug 0.3 --size-norm extent --lr 1.5e-4 --width {width} "
            "--init-from {runs}/boxnet-narrow/stage2/a3boxnet_narrow.onnx "
            "--distill-from {teacher} --distill-weight {distill_weight}")),
        Step("export with a parity check", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-narrow/gs/best.pt "
            "--out {runs}/boxnet-narrow/a3boxnet_narrow.onnx")),
        Step("int8 twin, calibrated on the superquadric bodies (ships only if it passes the accuracy rule, "
             "docs/models.md)", _a(
            "track3d-train quantize --data {data}/engine-train-sq --models-dir {runs}/boxnet-narrow "
            "--models a3boxnet_narrow")),
    ),
    notes=("`teacher` is the shipped full-width a3boxnet.onnx by name (or any A3BoxNet .onnx / checkpoint path, "
           "e.g. {runs}/boxnet-engine/a3boxnet.onnx after the a3boxnet-engine recipe).",
           "Stage 1 of the shipped model stopped at its 45 min budget after 40 epochs (best by validation at "
           "epoch 38); stage 2 ran its 100 min, 86 epochs, best by validation at epoch 76; stage 3 ran its "
           "75 min, 85 epochs, best by validation at epoch 83.",
           "The int8 twin calibrated on the points-only bodies (engine-train-po) failed the accuracy rule on "
           "held-out shapes (ACE_3d +0.017 m); calibrated on the superquadric bodies it passed (+0.007 m).",),
)

def _views_data(label: str, seed: int, knob: str, folder: str, generators: str = "") -> Step:
    return Step(label, _a(
        f"track3d-sim generate --preset {{preset}} --seed {seed} --train {{{knob}}} --test 0 --test-unseen 1 "
        f"--frames {{frames}} --points-only --sensors ideal,flash-lidar,tof {generators}"
        f"--out {{data}}/{folder} --workers {{workers}} --quiet"))


def _views_cache(folder: str) -> Step:
    return Step(f"cache: frustums beside the body's past views ({folder})", _a(
        f"track3d-train boxnet prepare --data {{data}}/{folder} --split train --jitters {{jitters}} --past-views "
        f"--out {{runs}}/boxnet-views/cache/{folder}.npz --quiet"),
        done_when=f"{{runs}}/boxnet-views/cache/{folder}.npz")


_VIEWS_SETS = ("views-a", "views-b", "views-c", "views-sq", "views-gs")

A3BOXNET_VIEWS = Recipe(
    name="a3boxnet-views",
    makes="{runs}/boxnet-views/a3boxnet_views.onnx",
    description="The default A3BoxNet (track3d.boxnet.DEFAULT_MODEL), given the body's past views "
                "(track3d.boxnet.PAST_VIEWS): the single-frame half-width model (a3boxnet_narrow.onnx) "
                "fine-tuned (~70 min on one thread, not distilled) on frustums of 60-frame points-only "
                "sequences, each beside the views the loop's track3d.body_views had gathered of the body by "
                "then, in that frame; the loop gives such a model its views (the single-frame model instead: "
                "--estimator-option model=a3boxnet_narrow.onnx).",
    knobs={"preset": "small", "a_train": 64, "b_train": 96, "c_train": 96, "sq_train": 48, "gs_train": 48,
           "frames": 60, "jitters": 2, "epoch_samples": 4000, "batch": 32, "max_steps": 0, "minutes": 70,
           "threads": 1, "workers": 1, "width": 0.5, "init": "a3boxnet_narrow.onnx"},
    tiny={"preset": "tiny", "a_train": 2, "b_train": 1, "c_train": 1, "sq_train": 1, "gs_train": 1, "frames": 8,
          "jitters": 1, "epoch_samples": 16, "batch": 8, "max_steps": 2, "minutes": 5},
    steps=(
        _views_data("data: 60-frame points-only bodies, range sensors mixed", 71, "a_train", "views-a"),
        _views_data("data: more of them (another seed)", 72, "b_train", "views-b"),
        _views_data("data: more of them (a third seed)", 73, "c_train", "views-c"),
        _views_data("data: 60-frame superquadric bodies", 74, "sq_train", "views-sq", "--generators superquadric "),
        _views_data("data: 60-frame Gaussian random spheres", 75, "gs_train", "views-gs",
                    "--generators gaussian_sphere "),
        *(_views_cache(f) for f in _VIEWS_SETS),
        Step("train: the default model fine-tuned on frustums beside the past views", _a(
            "track3d-train boxnet train --cache " + " ".join(f"{{runs}}/boxnet-views/cache/{f}.npz" for f in _VIEWS_SETS)
            + " --num-points 512 --epochs 200 --epoch-samples {epoch_samples} --batch {batch} --max-steps {max_steps} "
            "--flip-y --scale-aug 0.15 --no-category --threads {threads} --quiet --out {runs}/boxnet-views/run "
            "--time-budget-min {minutes} --stretch-aug 0.3 --size-norm extent --lr 3e-4 --width {width} "
            "--init-from {init}")),
        Step("export with a parity check (the metadata's past_views comes from the caches)", _a(
            "track3d-train boxnet export --force --checkpoint {runs}/boxnet-views/run/best.pt "
            "--out {runs}/boxnet-views/a3boxnet_views.onnx")),
    ),
    notes=("The shipped a3boxnet_views.onnx ran its 70 min, 133 epochs, best by validation AO_3d at epoch 132 "
           "(the validation sequences: every 8th of the caches', with their views).",
           "A control, the same fine-tune on the same frustums without the views (50 min), was level with the "
           "default model on the calibration sets (docs/models.md, 'A3BoxNet given the past views').",),
)


RECIPES: dict[str, Recipe] = {r.name: r for r in (A3BOXNET_ENGINE, A3BOXNET_NARROW, A3BOXNET_VIEWS, A3BOXNET_STEREO,
                                                  A3BOXNET_STEREO_NARROW, A3BOXNET_STEREO_BACKLIT, EDGETRACK_ENGINE, SIAMFC)}


def recipe(name: str) -> Recipe:
    try:
        return RECIPES[name]
    except KeyError:
        raise ValueError(f"unknown recipe {name!r} (known: {', '.join(RECIPES)})") from None


def knob_values(r: Recipe, tiny: bool = False, overrides: dict | None = None) -> dict:
    """The knobs of a run: the recipe's, the tiny variant's, then ``overrides`` (``--set``)."""
    k = dict(r.knobs)
    if tiny:
        k.update(r.tiny)
    for name, value in (overrides or {}).items():
        if name not in r.knobs:
            raise ValueError(f"recipe {r.name!r} has no knob {name!r} (knobs: {', '.join(r.knobs)})")
        k[name] = _typed(r, name, value)
    return k


def _typed(r: Recipe, name: str, value):
    """An overriding value as its knob's type (a whole number, a number or text), checked before
    any step runs: `minutes=abc` had failed only when the step using it was reached."""
    kind = type(r.knobs[name])
    if kind in (int, float) and not isinstance(value, bool):
        # a number knob takes any number (minutes=0.5 for a knob of 105; the step's own flag judges
        # whether it takes a fraction), kept whole when it is one, so the commands read as before
        try:
            v = float(str(value).strip())
        except (TypeError, ValueError):
            raise ValueError(f"knob {name!r} of recipe {r.name!r} takes a number like {r.knobs[name]!r}, "
                             f"got {value!r}") from None
        if v != v or v in (float("inf"), float("-inf")):
            raise ValueError(f"knob {name!r} of recipe {r.name!r} takes a finite number, got {value!r}")
        return int(v) if kind is int and v.is_integer() else v
    return value


def commands(r: Recipe, data: str | Path, runs: str | Path, tiny: bool = False,
             overrides: dict | None = None) -> list[tuple[Step, list[str], str | None]]:
    """[(step, argv, done_when path)] with every placeholder filled; the tiny variant drops the
    full-only steps."""
    values = {**knob_values(r, tiny, overrides), "data": str(data), "runs": str(runs)}
    out = []
    for s in r.steps:
        if tiny and s.full_only:
            continue
        argv = [a.format(**values) for a in s.argv]
        out.append((s, argv, s.done_when.format(**values) if s.done_when else None))
    return out


def _program(name: str) -> str:
    """The project's CLI next to this interpreter (the same virtual environment), else on PATH."""
    local = Path(sys.executable).parent / name
    found = str(local) if local.exists() else shutil.which(name)
    if not found:
        raise FileNotFoundError(f"{name} is not installed next to {sys.executable} nor on PATH "
                                f"(pip install -e '.[sim,train]')")
    return found


def _dies_with_recipe():
    """The preexec_fn of a step on Linux: SIGTERM to the step when the recipe dies, however it dies
    (prctl PR_SET_PDEATHSIG; a training then checkpoints and ends). A `kill -9` of the recipe had
    left its running trainer alive (PPID 1), and the recipe run again started a second one on the
    same run folder (the trainers refuse that now too: checkpoint.RunLock). None elsewhere."""
    import os

    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes

        prctl = ctypes.CDLL(None, use_errno=True).prctl   # looked up here, not between fork and exec
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def set_death_signal():
        prctl(1, int(signal.SIGTERM))      # PR_SET_PDEATHSIG
        if os.getppid() != parent:         # the recipe died before that: as if the signal had come
            os._exit(128 + int(signal.SIGTERM))

    return set_death_signal


# what the recipe passes on to the running step (SIGHUP, a closed terminal, as SIGTERM)
_FORWARDED = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


def _call(argv: list[str]) -> int:
    """Run one step and wait for it; its exit code. A signal to the recipe (Ctrl-C, SIGTERM,
    SIGHUP) goes to the step once (SIGHUP as SIGTERM): a training writes its checkpoint and ends,
    the recipe waits for that, then raises Interrupted. The step runs in a session of its own, so
    that a terminal's Ctrl-C does not reach it twice (a second signal ends a training at once);
    subprocess.call had killed it 0.25 s after Ctrl-C, in the middle of its checkpoint."""
    from .interrupt import Interrupted

    got: list[int] = []        # every signal the recipe received while the step ran
    pending: list[int] = []    # those not yet passed on (one that came before the step started)
    proc: list[subprocess.Popen] = []

    def pass_on():
        while proc and pending:
            signum = pending.pop(0)
            if proc[0].poll() is None:
                proc[0].send_signal(signal.SIGTERM if signum == getattr(signal, "SIGHUP", None) else signum)

    def forward(signum, frame):
        got.append(signum)
        pending.append(signum)
        pass_on()

    old = {}
    if threading.current_thread() is threading.main_thread():
        for s in _FORWARDED:
            if signal.getsignal(s) is not signal.SIG_IGN:
                old[s] = signal.signal(s, forward)
    try:
        proc.append(subprocess.Popen(argv, start_new_session=True, preexec_fn=_dies_with_recipe()))
        pass_on()
        rc = proc[0].wait()
    finally:
        for s, h in old.items():
            signal.signal(s, signal.SIG_DFL if h is None else h)
    if got:
        raise Interrupted(got[0])
    return rc


def run(r: Recipe, data: str | Path, runs: str | Path, tiny: bool = False, overrides: dict | None = None,
        dry_run: bool = False, log=print) -> int:
    """Run the steps in order; a failing step stops the recipe with its exit code (run again to
    resume), a signal with Interrupted once the step has stopped (`_call`). Returns 0 when every
    step succeeded or was already done."""
    steps = commands(r, data, runs, tiny, overrides)
    t_all = time.time()
    for i, (s, argv, done) in enumerate(steps, 1):
        head = f"[{i}/{len(steps)}] {s.label}"
        if done and Path(done).exists():
            log(f"{head}: done ({done} exists)")
            continue
        log(f"{head}\n    {shlex.join(argv)}")
        if dry_run:
            continue
        t0 = time.time()
        rc = _call([_program(argv[0]), *argv[1:]])
        if rc != 0:
            log(f"{head}: failed with exit code {rc}; run the recipe again to resume from here")
            return rc
        log(f"{head}: {time.time() - t0:.0f} s")
    if not dry_run:
        log(f"recipe {r.name}{' (tiny)' if tiny else ''}: done in {time.time() - t_all:.0f} s; "
            f"made {r.makes.format(runs=runs)}")
    return 0


def _parse_set(items: list[str]) -> dict:
    out = {}
    for item in items or []:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise ValueError(f"--set takes name=value, got {item!r}")
        try:
            out[name] = int(value)
        except ValueError:
            try:
                out[name] = float(value)
            except ValueError:
                out[name] = value
    return out


def build_parser():
    from track3d.argparsing import ArgumentParser, apply_formatter

    p = ArgumentParser(prog="track3d-train recipe", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("list", help="the recipes and what each makes")
    for cmd, text in (("show", "print the commands of a recipe"), ("run", "run a recipe (resumes)")):
        q = sub.add_parser(cmd, help=text)
        q.add_argument("name", help=f"recipe name: {', '.join(RECIPES)}")
        q.add_argument("--data", default="data", help="folder of the datasets")
        q.add_argument("--runs", default="runs", help="folder of caches, runs and exported models")
        q.add_argument("--tiny", action="store_true", help="the tiny variant (minutes; CI runs it)")
        q.add_argument("--set", nargs="*", default=[], metavar="KNOB=VALUE", help="override a knob (see `show`)")
        if cmd == "run":
            q.add_argument("--dry-run", action="store_true", help="print the steps without running them")
    return apply_formatter(p)


def main(argv: list[str] | None = None) -> int:
    a = build_parser().parse_args(argv)
    if a.cmd == "list":
        for r in RECIPES.values():
            print(f"{r.name:18s} {r.description}")
        return 0
    r = recipe(a.name)
    overrides = _parse_set(a.set)
    if a.cmd == "show":
        knobs = knob_values(r, a.tiny, overrides)   # a bad --set is the one line, before any output
        print(f"# {r.name}: {r.description}")
        print(f"# knobs: {knobs}")
        for note in r.notes:
            print(f"# note: {note}")
        for s, args, done in commands(r, a.data, a.runs, a.tiny, overrides):
            print(f"# {s.label}{f' (skipped when {done} exists)' if done else ''}")
            print(shlex.join(args))
        for s in r.steps:
            if a.tiny and s.full_only:
                print(f"# not in the tiny variant: {s.label} ({s.why})")
        return 0
    return run(r, a.data, a.runs, a.tiny, overrides, dry_run=a.dry_run)
