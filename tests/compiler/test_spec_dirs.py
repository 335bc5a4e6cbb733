"""Spec directories that are missing or hold no spec files are errors, not an empty domain."""

from __future__ import annotations

from adaptbench.compiler import compile_spec


def test_a_missing_spec_directory_is_s003(tmp_path):
    domain, diags = compile_spec([tmp_path / "nope"])
    assert domain is None and [d.code for d in diags] == ["S003"]


def test_a_directory_without_spec_files_is_s004(tmp_path):
    (tmp_path / "objects").mkdir()
    (tmp_path / "notes.txt").write_text("hello\n")
    domain, diags = compile_spec([tmp_path])
    assert domain is None and [d.code for d in diags] == ["S004"]
    assert "no spec files" in diags[0].message
