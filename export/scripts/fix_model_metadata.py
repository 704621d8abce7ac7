"""Correct the metadata of the shipped models in place (metadata only: the graph bytes are
asserted unchanged). Run once; idempotent.

    python export/scripts/fix_model_metadata.py [--models runtime/track3d/models]

What it fixes (the exporters now write all of this themselves):
- a3boxnet.onnx: `normalisation` described the "points" size coding while the model uses
  `size_norm: extent`; `train_data` was an absolute path of the training machine (now the
  dataset's folder name; `train_data_hash` identifies it);
- siamfc_*: no training-data identity: `train_data` now names the recipe of the data (the
  generator is deterministic), `train_data_hash` is null with a note (it was not recorded at
  training time and the data is not on this machine; a re-export of a new training fills it);
- all: ONNX's standard fields producer_name / producer_version / model_version / doc_string;
- variants (`<stem>_int8.onnx`): `parent_sha256` is the hash of the parent file as it is now
  (its metadata changed above; its graph did not).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from track3d.onnxmodel import MODELS_DIR
from track3d.size_coding import size_coding
from track3d_train.onnx_meta import read_metadata, rewrite_metadata

SIAMFC_DATA = ("track3d-sim generate --preset small --train 36 --test 18 --seed 0 (the 'med' dataset of "
               "the `siamfc` training recipe, track3d_train.recipes), split train")


def fixed(meta: dict) -> dict:
    m = dict(meta)
    if m.get("kind") == "a3boxnet":
        m["normalisation"] = size_coding(m.get("size_norm", "points")).description
        if isinstance(m.get("train_data"), str) and m["train_data"].startswith("/"):
            m["train_data"] = Path(m["train_data"]).name
    elif str(m.get("kind", "")).startswith("edgetrack") and "train_data" not in m:
        m["train_data"] = m.get("training", {}).get("data", "unknown")
        m["train_data_hash"] = None
        m["train_data_hash_note"] = ("not recorded by the exporter of this short-run model; train_data "
                                     "names the deterministic recipe of its data")
    elif str(m.get("kind", "")).startswith("siamfc"):
        m.setdefault("train_data", SIAMFC_DATA)
        if "train_data_hash" not in m:
            m["train_data_hash"] = None
            m["train_data_hash_note"] = ("not recorded when this model was trained; train_data names the "
                                         "deterministic recipe of its data")
    return m


def main(argv=None) -> int:
    import onnx

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", type=Path, default=MODELS_DIR, help="folder of the shipped models (default: %(default)s)")
    a = ap.parse_args(argv)
    # parents first: a variant records the hash of its parent file as rewritten here
    files = sorted(a.models.glob("*.onnx"), key=lambda f: (f.stem.endswith("_int8"), f.name))
    for f in files:
        meta = read_metadata(onnx.load(str(f)))
        new = fixed(meta)
        parent = a.models / str(meta.get("parent_model", ""))
        if meta.get("parent_sha256") and parent.is_file():
            import hashlib
            new["parent_sha256"] = hashlib.sha256(parent.read_bytes()).hexdigest()
        rewrite_metadata(f, new)
        changed = sorted(k for k in set(meta) | set(new) if meta.get(k) != new.get(k))
        print(f"{f.name}: metadata {'fixed: ' + ', '.join(changed) if changed else 'unchanged'}; "
              "standard ONNX fields set; graph bytes unchanged")
    return 0


if __name__ == "__main__":
    sys.exit(main())
