"""Tests of the generic atomic-write and unpacking helpers (downloads: see test_fetch.py)."""

import zipfile

import pytest

from skhmmgmr.datasets._download import atomic_open, extract_folders


def test_atomic_open_replaces_on_success_and_keeps_the_old_file_on_failure(tmp_path):
    path = tmp_path / "index.txt"
    path.write_text("old\n")
    with pytest.raises(KeyboardInterrupt), atomic_open(path) as f:
        f.write("half")
        raise KeyboardInterrupt
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.txt"]
    with atomic_open(path, "wb", suffix=".part") as f:
        f.write(b"new\n")
    assert path.read_bytes() == b"new\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.txt"]


def _zip(path, members):
    with zipfile.ZipFile(path, "w") as zf:
        for name, data in members:
            zf.writestr(name, data)
    return path


def test_extract_folders_moves_whole_folders_and_keeps_existing_ones(tmp_path):
    archive = _zip(
        tmp_path / "a.zip",
        [("top/one/x", b"1"), ("top/one/sub/y", b"2"), ("top/two/z", b"3"), ("top/skip", b"")],
    )
    root = tmp_path / "root"
    (root / "two").mkdir(parents=True)
    (root / "two" / "mine").write_text("kept")

    def folder_of(parts):
        return (parts[1], parts[2:]) if len(parts) > 2 else None

    extract_folders(archive, root, folder_of)
    assert (root / "one" / "x").read_bytes() == b"1"
    assert (root / "one" / "sub" / "y").read_bytes() == b"2"
    assert sorted(p.name for p in (root / "two").iterdir()) == ["mine"]
    assert sorted(p.name for p in root.iterdir()) == ["one", "two"]


def test_extract_folders_leaves_nothing_when_the_archive_is_refused(tmp_path):
    archive = _zip(tmp_path / "evil.zip", [("top/one/x", b"1"), ("top/../../escape", b"2")])
    root = tmp_path / "root"
    root.mkdir()
    with pytest.raises(ValueError, match="outside the target folder"):
        extract_folders(archive, root, lambda parts: (parts[0], parts[1:]))
    assert list(root.iterdir()) == []
