"""`track3d docs`: the documents help texts name, for a user with the package alone."""
from __future__ import annotations

import shutil

import pytest

from track3d import manual
from track3d.cli import main


def test_docs_lists_and_prints_the_documents(capsys):
    assert main(["docs"]) == 0
    names = [line.split()[0] for line in capsys.readouterr().out.splitlines()]
    assert set(names) == {"dataset", "models", "results", "runtime", "simulator", "readme"}
    assert main(["docs", "docs/runtime.md"]) == 0
    assert "## Embedding" in capsys.readouterr().out
    assert main(["docs", "README"]) == 0
    assert "## The two commands" in capsys.readouterr().out


def test_an_unknown_document_is_one_line(capsys):
    assert main(["docs", "nope"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "there are: dataset" in err


def test_a_wheel_reads_the_copy_it_carries(tmp_path, monkeypatch):
    """Without a checkout around the package, the copy CMakeLists.txt installs in track3d/docs."""
    pkg = tmp_path / "site" / "track3d"
    (pkg / "docs").mkdir(parents=True)
    for p in manual.doc_paths().values():
        shutil.copy(p, pkg / "docs" / p.name)
    monkeypatch.setattr(manual, "_PACKAGE", pkg)
    assert manual.docs_dir() == pkg / "docs"
    assert set(manual.doc_paths()) == {"dataset", "models", "results", "runtime", "simulator", "readme"}
    assert manual.doc_paths()["readme"] == pkg / "docs" / "README.md"
    shutil.rmtree(pkg / "docs")
    with pytest.raises(ValueError, match="no documents installed"):
        manual.doc_text("runtime")


def test_the_wheel_is_built_with_the_documents():
    """The copy the wheel carries is CMakeLists.txt's install rule (a wheel build takes too long here)."""
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "CMakeLists.txt").read_text()
    assert "docs/*.md" in text and "DESTINATION track3d/docs" in text
