"""`track3d-sim`: generate | restereo | stats | preview | ply | shapes. Errors print one line naming the problem, exit 2."""
from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from track3d.argparsing import ArgumentParser, apply_formatter, exit_for_missing_extra, hidden_alias, package_version

from .errors import SimError
from .generate import PRESETS
from .generators import GENERATORS, default_generators
from .sensors import DEPTH_SENSORS


# What the simulator imports beyond the runtime (top-level module -> the extra installing it):
# the base install also has the track3d-sim command, which must say so, not end in a traceback.
EXTRA_MODULES = {**{m: "sim" for m in ("trimesh", "embreex", "PIL", "tqdm", "matplotlib", "scipy", "skimage")},
                 "ray": "cluster"}


def _resolution(text: str):
    try:
        w, h = text.lower().split("x")
        return int(w), int(h)
    except ValueError:
        raise argparse.ArgumentTypeError(f"resolution must look like 640x480, got {text!r}") from None


def _phase_range(text: str):
    """LO:HI in degrees; the range itself is checked by make_settings."""
    try:
        lo, hi = text.split(":")
        return float(lo), float(hi)
    except ValueError:
        raise argparse.ArgumentTypeError(f"sun phase must look like 100:150 (degrees), got {text!r}") from None


# A size written with a unit: "0.5km", "800 m", "2.5e3mm"
_SIZE_WITH_UNIT = re.compile(r"\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z]+)\s*")
_METRES_PER = {"m": 1.0, "km": 1000.0, "cm": 0.01, "mm": 0.001}


def _mesh(text: str):
    """PATH or PATH:SIZE_M"""
    path, size = text, None
    if ":" in text:
        head, tail = text.rsplit(":", 1)
        try:
            size = float(tail)
            path = head
        except ValueError:
            unit = _SIZE_WITH_UNIT.fullmatch(tail)
            if unit and not Path(text).exists():  # a file named so is a file; else a size with a unit
                # it had been taken for part of the file's name: "user mesh rock.obj:0.5km does not exist"
                metres = _METRES_PER.get(unit.group(2).lower())
                say = f": for {unit.group(1)} {unit.group(2)} write {head}:{float(unit.group(1)) * metres:g}" \
                    if metres is not None else ""
                raise argparse.ArgumentTypeError(f"mesh size (PATH:SIZE) is a plain number of metres, without a "
                                                 f"unit, got {tail!r}{say}")
        if size is not None and not (size > 0 and size < float("inf")):
            raise argparse.ArgumentTypeError(f"mesh size must be a positive number of metres, got {tail!r}")
    return {"path": path, "size_m": size}


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="track3d-sim", description="3D asteroid tracking dataset simulator "
                                "(headless CPU ray casting; writes the layout of docs/dataset.md).")
    p.add_argument("--version", action="version", version=f"%(prog)s {package_version()}")
    sub = p.add_subparsers(dest="cmd", required=True, metavar="{generate,restereo,stats,preview,ply,shapes,demo}")
    g = sub.add_parser("generate", help="render a dataset (resumable, deterministic for a seed)",
                       description="Render a dataset into --out. A killed run continues where it stopped "
                       "when started again with the same arguments; dataset.json is written last.")
    g.add_argument("--preset", choices=sorted(PRESETS), default="small",
                   help="tiny: 160x120, 4+2 seqs x 8 frames (tests); small: 640x480, 18+9 x 100; "
                        "paper: 640x480, 360+135 x 300 (default: small)")
    g.add_argument("--out", required=True, help="output folder (created; must be new, or a run of the same settings)")
    g.add_argument("--seed", type=int, default=0, help="global seed (default 0)")
    g.add_argument("--workers", type=int, default=1, help="processes (default 1); output bytes do not depend on it")
    g.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                   help="render with Ray, one task per sequence: without ADDRESS a local Ray instance, else a "
                        "running cluster (auto, HOST:6379, ray://HOST:10001; --out must be on a filesystem every "
                        "node mounts). Needs the 'cluster' extra; output bytes are the same (default: off)")
    g.add_argument("--resolution", type=_resolution, help="WxH, e.g. 640x480 (default: from the preset)")
    g.add_argument("--fov", type=float, dest="fov_x_deg",
                   help="horizontal perspective angle in degrees; the vertical follows for square pixels "
                        "(default: from the preset)")
    g.add_argument("--frames", type=int, help="frames per sequence (default: from the preset)")
    g.add_argument("--train", type=int, help="number of training sequences (default: from the preset)")
    g.add_argument("--test", type=int, help="number of test sequences (fine categories unseen in train; "
                                            "default: from the preset)")
    g.add_argument("--test-unseen", type=int, dest="test_unseen",
                   help="number of unseen-shapes test sequences: generators held out of train and test "
                        "(default: the preset's, 0)")
    g.add_argument("--unseen-generators", dest="unseen_generators", metavar="A,B",
                   help=f"generators to hold out for --test-unseen (from {', '.join(GENERATORS)}; default: "
                        f"the rule of sequence.UNSEEN_GENERATORS, see docs/simulator.md 'Splits')")
    g.add_argument("--generators", dest="shape_generators", metavar="A,B",
                   help=f"shape generators of the train and test splits (from {', '.join(GENERATORS)}; default: "
                        f"{', '.join(default_generators())}; the others are opt-in)")
    g.add_argument("--sensors", default=None, metavar="A,B",
                   help=f"depth sensors, cycled over the sequences (default: ideal; from "
                        f"{', '.join(DEPTH_SENSORS)})")
    g.add_argument("--points-only", action="store_true", dest="points_only",
                   help="write depth, labels and meta only (no images, no shading): box-network data "
                        "(default: off)")
    g.add_argument("--auto-exposure", action="store_true", dest="auto_exposure",
                   help="per-sequence auto exposure: longer exposure, then gain, in low light, with the "
                        "noise that implies (docs/simulator.md 'Camera effects'; default: off, fixed camera)")
    g.add_argument("--motion-blur", action="store_true", dest="motion_blur",
                   help="blur fast frames by averaging sub-exposure renders (default: off)")
    g.add_argument("--sun-phase", type=_phase_range, dest="sun_phase", metavar="LO:HI",
                   help="draw each sequence's phase angle (sun-body-camera, degrees) uniformly in LO..HI, "
                        "0 <= LO <= HI <= 170, e.g. 100:150 for a set of crescents lit from behind; the "
                        "sequences keep their bodies, motions and scenes (default: the natural mix, "
                        "|N(0, 55)| capped at 150, mostly front-lit)")
    g.add_argument("--false-alarms", type=float, dest="false_alarms", metavar="RATE",
                   help="per-pixel, per-frame probability of a false return of the range sensors (ideal, "
                        "tof, flash-lidar; not stereo): a range drawn in the sensor's gate, before the surface, "
                        "e.g. 1e-5, about 3 a frame at 640x480 (default: 0, none)")
    g.add_argument("--subdivisions", type=int, help="icosphere subdivisions of procedural meshes (6 = 82k faces; "
                                                    "default: from the preset)")
    g.add_argument("--mesh", action="append", type=_mesh, default=[], metavar="PATH[:SIZE_M]",
                   help="use a user mesh (OBJ/PLY/STL...) as the shape of the sequences (repeat to cycle "
                        "through several); SIZE_M = the body's length along its longest axis in metres, a plain "
                        "number (default: the sampled box volume; "
                        "the file's own units are ignored); a size the scenes cannot hold (about 0.1-42 m for a "
                        "round body; past ~21 m it fills the view: a warning) is refused with the range for "
                        "that shape")
    g.add_argument("--mesh-dir", dest="mesh_dir", metavar="DIR",
                   help="use every mesh file of DIR that trimesh reads (cycled over the sequences, in name order) "
                        "as the bodies, scaled to the sampled box volume (default: procedural generators)")
    g.add_argument("--overwrite", action="store_true", help="delete an existing track3d-sim output folder first")
    g.add_argument("--quiet", dest="no_progress", action="store_true", help="no progress bar")
    hidden_alias(g, "--no-progress", "no_progress", action="store_true")  # the name before --quiet

    r = sub.add_parser("restereo", help="recompute a stereo dataset's depth maps from its images with this "
                       "release's matcher (no rendering; resumable)",
                       description="Recompute the depth maps of every stereo sequence of ROOT from its left/right "
                       "images with this release's stereo matcher (track3d.stereo), as `generate` would now write "
                       "them, and record the matcher's settings in each sequence's meta.json. Sequences already "
                       "made with these settings, and sequences of other depth sensors, are left alone; a killed "
                       "run continues where it stopped when started again.")
    r.add_argument("root", help="dataset root (the folder holding dataset.json)")
    r.add_argument("--quiet", dest="no_progress", action="store_true", help="no progress bar")
    s = sub.add_parser("stats", help="the paper's Fig. 4 plots (size classes, box volumes, speeds, illumination)")
    s.add_argument("root", help="dataset folder (with dataset.json)")
    s.add_argument("--out", required=True, help="output image: .png, or .pdf, .svg, ... (any format matplotlib "
                                                "writes); its folder is created")
    s.add_argument("--split", choices=["train", "test", "test_unseen", "all"], default="all",
                   help="split to plot (default: all)")

    v = sub.add_parser("preview", help="contact sheet (PNG) or animation (GIF) of a sequence with its boxes")
    v.add_argument("sequence", help="sequence folder, e.g. DATA/train/0001")
    v.add_argument("--out", required=True, help="output .png / .jpg (contact sheet) or .gif (animation); "
                                                "its folder is created")
    v.add_argument("--frames", type=int, default=12, help="frames in the contact sheet, >= 1 (default 12)")
    v.add_argument("--gain", type=float, default=1.0, help="brightness gain (> 0) for viewing dark images (default 1)")
    v.add_argument("--right", action="store_true", help="add the right image beside the left")
    dm = sub.add_parser("demo", help="simulate a small test set, run Track3D with the shipped models, evaluate, "
                                      "write plots and an overlay (the README's main job)")
    from .demo import add_arguments
    add_arguments(dm)
    e = sub.add_parser("ply", help="export a frame's back-projected point cloud (with colours) as PLY")
    e.add_argument("sequence", help="sequence folder, e.g. DATA/train/0001")
    e.add_argument("--frame", type=int, default=1, help="1-based frame number (default 1)")
    e.add_argument("--out", required=True, help="output .ply file; its folder is created")
    c = sub.add_parser("shapes", help="contact sheet (PNG) of bodies from the shape generators, lit by a sun")
    c.add_argument("--out", required=True, help="output .png / .jpg; its folder is created")
    c.add_argument("--generator", action="append", default=[], metavar="NAME",
                   help="generator to show (repeat for several; default: every registered generator)")
    c.add_argument("--count", type=int, default=6, help="bodies per generator (default 6)")
    c.add_argument("--seed", type=int, default=0, help="seed (default 0)")
    c.add_argument("--detail", type=int, default=5, help="mesh detail 1..8 (default 5; the datasets use 6)")
    c.add_argument("--cell", type=int, default=192, help="pixels per body image, >= 16 (default 192)")
    c.add_argument("--quiet", dest="no_progress", action="store_true", help="no progress bar")
    hidden_alias(c, "--no-progress", "no_progress", action="store_true")
    return apply_formatter(p)


def _join_dash_values(argv: list[str]) -> list[str]:
    """`--resolution -320x240` -> `--resolution=-320x240` (and `--sun-phase -5:20`): argparse takes a value starting with "-"
    (other than a plain negative number) for a flag and says "expected one argument"; joined, the
    value reaches its check, which names what is wrong with it."""
    out, i = [], 0
    while i < len(argv):
        if argv[i] in ("--resolution", "--sun-phase") and i + 1 < len(argv) and re.match(r"-\d", argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv: list[str] | None = None) -> int:
    """The `track3d-sim` console script; its warnings print as one line (argparsing.one_line_warnings)."""
    from track3d.argparsing import one_line_warnings

    with one_line_warnings("track3d-sim"):
        return _main(argv)


def _main(argv=None) -> int:
    from track3d.dataset import DatasetError

    parser = build_parser()
    args = parser.parse_args(_join_dash_values(sys.argv[1:] if argv is None else argv))
    try:
        if args.cmd == "generate":
            from .generate import generate, make_settings
            w, h = args.resolution if args.resolution else (None, None)
            settings = make_settings(args.preset, args.seed, width=w, height=h, fov_x_deg=args.fov_x_deg,
                                     frames=args.frames, train=args.train, test=args.test,
                                     subdivisions=args.subdivisions, meshes=args.mesh or None,
                                     test_unseen=args.test_unseen, unseen_generators=args.unseen_generators,
                                     sensors=args.sensors, points_only=args.points_only or None,
                                     mesh_dir=args.mesh_dir, auto_exposure=args.auto_exposure or None,
                                     motion_blur=args.motion_blur or None,
                                     shape_generators=args.shape_generators, sun_phase=args.sun_phase,
                                     false_alarms=args.false_alarms)
            generate(settings, args.out, workers=args.workers, overwrite=args.overwrite,
                     progress=not args.no_progress, ray=args.ray)
        elif args.cmd == "restereo":
            from .restereo import restereo
            c = restereo(args.root, progress=not args.no_progress)
            print(f"track3d-sim restereo: {c['recomputed']} sequences recomputed ({c['frames']} depth maps), "
                  f"{c['current']} already current, {c['other']} of other depth sensors left alone")
        elif args.cmd == "stats":
            from .stats import plot_stats
            st = plot_stats(args.root, args.out, args.split)
            # one line naming the file, as `preview` does: it had printed nothing
            print(f"track3d-sim stats: {st['n_seq']} sequences, {st['n_frames']} frames ({args.split}) "
                  f"-> {Path(args.out)}")
        elif args.cmd == "preview":
            from .preview import preview, shown_frames
            out = preview(args.sequence, args.out, n=args.frames, gain=args.gain, right=args.right)
            shown, total = shown_frames(args.sequence, args.out, args.frames)
            more = f" (--frames {args.frames}, the sequence has {total})" if args.frames > total and \
                Path(out).suffix.lower() != ".gif" else ""
            print(f"track3d-sim preview: {shown} of {total} frames{more} -> {out}")
        elif args.cmd == "ply":
            from .preview import export_ply, ply_vertices
            out = export_ply(args.sequence, args.frame, args.out)
            n = ply_vertices(out)
            # an empty cloud is a valid file but rarely what was wanted: a body past a range
            # sensor's reach, or a frame without it (it had printed as any other)
            why = " (no depth return on this frame: the body past the sensor's range, or out of view)" if n == 0 else ""
            print(f"track3d-sim ply: frame {args.frame} of {args.sequence}, {n} points{why} -> {out}")
        elif args.cmd == "demo":
            from track3d.onnxmodel import ModelError
            from .demo import run_demo
            try:
                return run_demo(args)
            except (DatasetError, ModelError, ValueError, RuntimeError, OSError) as e:
                raise SimError(str(e)) from None
        elif args.cmd == "shapes":
            from .contact_sheet import contact_sheet
            out = contact_sheet(args.out, args.generator or None, count=args.count, seed=args.seed, detail=args.detail,
                                cell=args.cell, progress=not args.no_progress)
            print(f"track3d-sim shapes: {args.count} bodies per generator -> {out}")
    except (SimError, DatasetError, OSError) as e:  # damaged data met while reading frames, an unwritable --out
        print(f"track3d-sim: error: {e}", file=sys.stderr)
        return 2
    except ModuleNotFoundError as e:
        return exit_for_missing_extra(e, EXTRA_MODULES, f"track3d-sim {args.cmd}")
    except KeyboardInterrupt:
        print("track3d-sim: interrupted (run the same command again to resume)", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
