"""The package's one rule for writing output files (skhmmgmr._core._files)."""

import os

import pytest

from skhmmgmr._core._files import check_output_paths, write_atomically


def test_write_atomically_writes_text_bytes_and_through_a_writer(tmp_path):
    target = tmp_path / "new" / "nested" / "out.txt"
    assert write_atomically(target, "é\n") == target
    assert target.read_text(encoding="utf-8") == "é\n"
    write_atomically(target, b"\x00\x01")
    assert target.read_bytes() == b"\x00\x01"
    write_atomically(target, write=lambda partial: partial.write_text("via writer"))
    assert target.read_text() == "via writer"
    assert sorted(p.name for p in target.parent.iterdir()) == ["out.txt"]


def test_write_atomically_never_follows_a_planted_link(tmp_path):
    outside = tmp_path / "outside.txt"
    outside.write_text("precious")
    folder = tmp_path / "out"
    folder.mkdir()
    # every name a fixed-name writer would have used
    for name in (".model.h.partial", f".partial-{os.getpid()}-model.h", ".model.h.tmp"):
        (folder / name).symlink_to(outside)
    write_atomically(folder / "model.h", "generated")
    assert outside.read_text() == "precious"
    assert (folder / "model.h").read_text() == "generated"


def test_write_atomically_removes_the_partial_file_on_failure(tmp_path):
    def failing(partial):
        partial.write_text("half")
        raise RuntimeError("interrupted")

    with pytest.raises(RuntimeError, match="interrupted"):
        write_atomically(tmp_path / "out.csv", write=failing)
    assert list(tmp_path.iterdir()) == []


def test_write_atomically_takes_exactly_one_source(tmp_path):
    with pytest.raises(TypeError, match="exactly one"):
        write_atomically(tmp_path / "a", "x", write=lambda p: None)
    with pytest.raises(TypeError, match="exactly one"):
        write_atomically(tmp_path / "a")


def test_check_output_paths_names_the_option(tmp_path):
    existing = tmp_path / "model.json"
    existing.write_text("{}")
    with pytest.raises(FileExistsError, match=r"--metrics .*model.json exists; pass --overwrite"):
        check_output_paths([existing], overwrite=False, option="--metrics")
    with pytest.raises(FileExistsError, match="overwrite=True"):
        check_output_paths([existing], overwrite=False, option="directory")
    check_output_paths([existing], overwrite=True, option="--metrics")
    with pytest.raises(IsADirectoryError, match="--output .* is a folder"):
        check_output_paths([tmp_path], overwrite=True, option="--output")
    missing = tmp_path / "a" / "b" / "c.txt"
    check_output_paths([missing], overwrite=False)
    with pytest.raises(NotADirectoryError, match="does not exist"):
        check_output_paths([missing], overwrite=False, create_folders=False)
    assert not (tmp_path / "a").exists()  # a check never creates anything
    with pytest.raises(NotADirectoryError, match="is not a folder"):
        check_output_paths([existing / "x.c"], overwrite=False)
