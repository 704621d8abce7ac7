"""The project's documents, for a user who has the package and not the repository.

Help texts and error messages name `docs/runtime.md` and its siblings; a wheel carries them in
`track3d/docs/` (CMakeLists.txt installs them), and a checkout (an editable install) reads its own
`docs/`, so that what is shown is what is beside the code. `track3d docs` lists them and prints one.
"""
from __future__ import annotations

from pathlib import Path

__all__ = ["docs_dir", "doc_paths", "doc_text"]

_PACKAGE = Path(__file__).resolve().parent


def docs_dir() -> Path | None:
    """The folder of the documents: the checkout's `docs/` when this package runs from one (its
    files are the current ones), else the copy the wheel carries; None when neither is there."""
    checkout = _PACKAGE.parents[1] / "docs"
    if (checkout / "runtime.md").is_file() and (_PACKAGE.parents[1] / "README.md").is_file():
        return checkout
    shipped = _PACKAGE / "docs"
    return shipped if (shipped / "runtime.md").is_file() else None


def doc_paths() -> dict[str, Path]:
    """{name: path} of every document, the README as 'readme' ({} when none is installed)."""
    d = docs_dir()
    if d is None:
        return {}
    out = {p.stem.lower(): p for p in sorted(d.glob("*.md")) if p.stem.lower() != "readme"}
    readme = d / "README.md" if d == _PACKAGE / "docs" else d.parent / "README.md"   # the wheel's copy sits beside
    if readme.is_file():
        out["readme"] = readme
    return out


def doc_text(name: str) -> str:
    """The text of document `name` ('runtime', 'docs/runtime.md', 'README'...); ValueError names
    the ones there are."""
    key = Path(name).stem.lower()
    paths = doc_paths()
    if not paths:
        raise ValueError("no documents installed with this track3d (a wheel built without them)")
    if key not in paths:
        raise ValueError(f"no document {name!r}; there are: {', '.join(paths)}")
    return paths[key].read_text(encoding="utf-8")
