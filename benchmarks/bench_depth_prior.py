"""How deep is a body the depth sensor does not reach? Rules for its depth extent from its two
lateral extents, scored on the simulator's bodies.

Where a range-limited sensor gives no usable return (the body past a ToF camera's range, or cut
by it), the loop boxes the body from the image: front face at the nearest return or the range,
cross-section from the 2D box, and the depth extent guessed from the two lateral extents
(`track3d.range_cut.view_depth`: their mean). This scores that rule and others against the true
boxes of bodies from the training world (every generator the A3BoxNet recipes train on) and,
separately, the held-out generators, at attitudes drawn uniformly or from the simulator's own
motion (its spin about the body's inertia axes over a 30 s sequence).

The score of a guess is min(d, g) / max(d, g) for the true depth extent d and the guess g: the
IoU_3d of two boxes that share the front face and the cross-section. Rules of lo = min(sx, sy),
hi = max(sx, sy): the mean (the loop's rule), lo, hi, sqrt(lo hi) ("geo mean"), and k lo^a hi^(1 - a) with k and a
fitted on the training world (the held-out generators only report).

    python benchmarks/bench_depth_prior.py --bodies 20 --attitudes 50 --out bench-results/depth_prior

Writes <out>/depth_prior.json and the table (<out>/depth_prior.md), and prints it.
"""
from __future__ import annotations

import numpy as np
from benchlib.output import add_out_argument
from benchlib.record import finish_record, start_record

from track3d.argparsing import ArgumentParser, bounded, run_main
from track3d.jsonable import write_json
from track3d.progress import progress
from track3d.range_cut import view_depth

ATTITUDES = ("uniform", "motion")
# the fitted rule's grid: k in [0.6, 1.4], a in [0, 1.5] (a > 1: deeper for flatter outlines)
K_GRID = np.round(np.arange(0.60, 1.401, 0.02), 2)
A_GRID = np.round(np.arange(0.0, 1.501, 0.05), 2)


def training_world() -> tuple[str, ...]:
    """The generators the shipped A3BoxNets train on: the default pool without the held-out ones,
    plus the opt-in superquadric and Gaussian-sphere bodies (track3d_train.recipes)."""
    from track3d_sim.generators import default_generators
    from track3d_sim.sequence import UNSEEN_GENERATORS
    return tuple(g for g in default_generators() if g not in UNSEEN_GENERATORS) + ("superquadric", "gaussian_sphere")


def held_out() -> tuple[str, ...]:
    from track3d_sim.sequence import UNSEEN_GENERATORS
    return tuple(UNSEEN_GENERATORS)


def depth_score(depth: np.ndarray, guess: np.ndarray) -> float:
    """Mean of min(d, g) / max(d, g) over the bodies: depth, guess (n,) > 0."""
    d, g = np.asarray(depth, np.float64), np.asarray(guess, np.float64)
    return float(np.mean(np.minimum(d, g) / np.maximum(d, g)))


def power_rule(extents: np.ndarray, k: float, a: float) -> np.ndarray:
    """k lo^a hi^(1 - a) of each row's lateral extents; extents (n, 3) [sx, sy, sz]."""
    lo = np.minimum(extents[:, 0], extents[:, 1])
    hi = np.maximum(extents[:, 0], extents[:, 1])
    return k * lo ** a * hi ** (1.0 - a)


def rules(extents: np.ndarray, k: float, a: float) -> dict[str, np.ndarray]:
    """Each rule's guess (n,) of the depth extent from extents (n, 3)."""
    return {"mean": view_depth(extents[:, 0], extents[:, 1]),
            "min": power_rule(extents, 1.0, 1.0), "max": power_rule(extents, 1.0, 0.0),
            "geo mean": power_rule(extents, 1.0, 0.5), "fitted": power_rule(extents, k, a)}


def fit_power_rule(extents: np.ndarray) -> tuple[float, float, float]:
    """(k, a, score) of the best k lo^a hi^(1 - a) on the grid for extents (n, 3)."""
    best = (0.0, 0.0, -1.0)
    for a in A_GRID:
        base = power_rule(extents, 1.0, float(a))
        for k in K_GRID:
            s = depth_score(extents[:, 2], k * base)
            if s > best[2]:
                best = (float(k), float(a), s)
    return best


def uniform_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) rotations uniform over SO(3) (from normalised Gaussian quaternions)."""
    from track3d_sim.shapes import quat_to_matrix
    q = rng.normal(size=(n, 4))
    return quat_to_matrix(q / np.linalg.norm(q, axis=1, keepdims=True))


def sample_extents(generator: str, bodies: int, attitudes: int, seed: int, mode: str,
                   detail: int = 4) -> np.ndarray:
    """(bodies * attitudes, 3) extents [sx, sy, sz] in the camera frame of `bodies` bodies of
    `generator`, each at `attitudes` attitudes (mode "uniform" or "motion": frames spread over a
    300-frame sequence of the simulator's motion)."""
    from track3d_sim.generate import PRESETS
    from track3d_sim.generators import make_body
    from track3d_sim.motion import make_motion

    from track3d.camera import Camera
    p = PRESETS["small"]
    tan_half = Camera.from_fov(p["width"], p["height"], p["fov_x_deg"]).tan_half
    rng = np.random.default_rng([seed, sum(map(ord, generator))])
    out = []
    for _ in range(bodies):
        shape = make_body(generator, rng, 300.0, detail)
        if mode == "uniform":
            R = uniform_rotations(rng, attitudes)
        else:
            R = make_motion(rng, 300, shape.radius, tan_half, inertia=shape.inertia())["R"]
            R = R[np.linspace(0, len(R) - 1, attitudes).round().astype(int)]
        X = np.einsum("vj,nij->nvi", shape.vertices, R)
        out.append(X.max(axis=1) - X.min(axis=1))
    return np.concatenate(out)


def measure(bodies: int, attitudes: int, seed: int, detail: int = 4) -> dict:
    """Per attitude mode: the rule fitted on the training world and every rule's score, pooled
    over the training world, over the held-out generators, and per generator."""
    train, held = training_world(), held_out()
    out = {}
    for mode in ATTITUDES:
        ext = {g: sample_extents(g, bodies, attitudes, seed, mode, detail)
               for g in progress([*train, *held], desc=f"bodies ({mode})")}
        pooled_train = np.concatenate([ext[g] for g in train])
        k, a, _ = fit_power_rule(pooled_train)
        groups = {"training world": pooled_train, "held-out": np.concatenate([ext[g] for g in held]), **ext}
        out[mode] = {"fitted": {"k": k, "a": a},
                     "scores": {name: {r: depth_score(e[:, 2], guess) for r, guess in rules(e, k, a).items()}
                                for name, e in groups.items()},
                     "bodies": {name: int(len(e)) for name, e in groups.items()}}
    return out


def table(result: dict) -> str:
    lines = []
    for mode, r in result.items():
        names = list(next(iter(r["scores"].values())))
        lines.append(f"attitudes: {mode}; fitted rule {r['fitted']['k']:.2f} lo^{r['fitted']['a']:.2f} "
                     f"hi^{1 - r['fitted']['a']:.2f} (on the training world)")
        lines.append(f"{'bodies':18s} " + " ".join(f"{n[:14]:>14s}" for n in names))
        for g, s in r["scores"].items():
            lines.append(f"{g:18s} " + " ".join(f"{s[n]:14.3f}" for n in names))
        lines.append("")
    return "\n".join(lines).rstrip()


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bodies", type=bounded(int, 1), default=20, help="bodies per generator")
    ap.add_argument("--attitudes", type=bounded(int, 1), default=50, help="attitudes per body")
    ap.add_argument("--seed", type=int, default=1, help="random seed")
    ap.add_argument("--detail", type=bounded(int, 1, high=8), default=4, help="mesh detail of the bodies")
    add_out_argument(ap, "depth_prior")
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    rec = start_record("depth_prior", bodies=a.bodies, attitudes=a.attitudes, seed=a.seed, detail=a.detail)
    rec["results"] = measure(a.bodies, a.attitudes, a.seed, a.detail)
    a.out.mkdir(parents=True, exist_ok=True)
    write_json(a.out / "depth_prior.json", finish_record(rec))
    text = table(rec["results"])
    (a.out / "depth_prior.md").write_text("```\n" + text + "\n```\n")
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(run_main(main, "bench_depth_prior.py"))
