"""What an archive may make the package unpack, and hold in memory, and how its faults are named
(issue #35, items 1, 2 and 13).

Chunk-like archives are built here from the comma2k19 sample (segment 40 of its route) with one
hostile or outsized member, and read by range reads (file:// URL) and whole (``method=
"archive"``). A member over what it may hold refuses the archive, names the member, and leaves
nothing in the cache; range reads hold a bounded number of bytes in memory whatever the size
of the members; a cached segment the loader refuses as damaged is removed from the cache.
"""

import io
import re
import tracemalloc
import zipfile

import numpy as np
import pytest
from _comma2k19_data import ROUTE, SEGMENT
from _http_server import Server

from skhmmgmr.datasets import _download, fetch_comma2k19, load_comma2k19_segment
from skhmmgmr.datasets._comma2k19 import _fetch
from skhmmgmr.datasets._remote import read_manifest

pytest.importorskip("fsspec")
pytest.importorskip("aiohttp")

NAME = f"{ROUTE}/40"


def _member(relative):
    return f"Chunk_1/{ROUTE}/40/{relative}"


def _chunk(folder, extra=(), skip=()):
    """Chunk_1.zip in ``folder`` with the sample's files (but ``skip``) and the ``extra``
    (relative path, bytes, compression) members; return its file:// base URL."""
    folder.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(folder / "Chunk_1.zip", "w", compression=zipfile.ZIP_STORED) as zf:
        for file in sorted(p for p in SEGMENT.rglob("*") if p.is_file()):
            relative = file.relative_to(SEGMENT).as_posix()
            if relative not in skip:
                zf.write(file, _member(relative))
        for relative, data, compression in extra:
            zf.writestr(_member(relative), data, compress_type=compression)
    return folder.as_uri() + "/"


def _nothing_kept(home):
    segments = [p for p in (home / "comma2k19").rglob("*") if p.is_dir() and p.name == "40"]
    hidden = [p for p in home.rglob(".*")]
    return not segments and not hidden


@pytest.mark.parametrize("method", ["range", "archive"])
@pytest.mark.parametrize(
    "megabytes, reason",
    [
        (200, "more than the 67108864 such a member may hold"),
        (20, r"\d+ times its compressed size \(at most 100\)"),
    ],
)
def test_a_compression_bomb_is_refused_naming_the_member(tmp_path, method, megabytes, reason):
    """Zeros deflate about 1000 times: 200 MB to 0.2 MB is over the size a signal file may
    have, 20 MB (under it) over the ratio."""
    bomb = "processed_log/CAN/raw_can/t"
    zeros = bytes(megabytes << 20)
    url = _chunk(tmp_path / "mirror", [(bomb, zeros, zipfile.ZIP_DEFLATED)], skip={bomb})
    home = tmp_path / "home"
    pattern = rf"{re.escape(repr(_member(bomb)))}.*would unpack to {megabytes << 20} bytes.*"
    with pytest.raises(OSError, match=pattern + reason):
        fetch_comma2k19(segments=NAME, data_home=home, base_url=url, method=method)
    assert _nothing_kept(home)


@pytest.mark.parametrize("method", ["range", "archive"])
def test_a_member_larger_than_such_a_file_may_be_is_refused(tmp_path, method, monkeypatch):
    monkeypatch.setattr(_fetch, "_FILE_SIZE", 1 << 20)
    big = "processed_log/CAN/raw_can/extra"
    data = np.random.default_rng(0).bytes(3 << 20)  # incompressible: the ratio is 1
    url = _chunk(tmp_path / "mirror", [(big, data, zipfile.ZIP_DEFLATED)])
    home = tmp_path / "home"
    pattern = rf"{re.escape(repr(_member(big)))}.*{3 << 20} bytes, more than the {1 << 20}"
    with pytest.raises(OSError, match=pattern):
        fetch_comma2k19(segments=NAME, data_home=home, base_url=url, method=method)
    assert _nothing_kept(home)


def test_a_member_writing_more_than_it_declares_is_stopped():
    target = io.BytesIO(bytes(5000))
    with pytest.raises(OSError, match="'m' of the archive 'a.zip' unpacks to more than the 4096"):
        _download._copy_member(target, "/dev/null", 4096, "m", "a.zip")


def test_the_video_may_hold_more_than_the_signals():
    assert _fetch.member_cap(("Chunk_1", "r", "40", "video.hevc")) == 256 << 20
    assert _fetch.member_cap(("Chunk_1", "r", "40", "processed_log", "CAN", "t")) == 64 << 20


def test_range_reads_hold_a_bounded_part_of_a_large_member(tmp_path):
    """A 48 MB member (under the 64 MB cap) is prefetched through a temporary file: the peak
    of the memory Python allocates stays under 32 MB (it was at least twice the member)."""
    size = 48 << 20
    large = "processed_log/CAN/large/value"
    data = np.random.default_rng(1).bytes(size)
    url = _chunk(tmp_path / "mirror", [(large, data, zipfile.ZIP_STORED)])
    home = tmp_path / "home"
    tracemalloc.start()
    try:
        frame = fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 32 << 20, f"peak {peak / 2**20:.1f} MiB"
    cached = home / "comma2k19" / ROUTE.replace("|", "--") / "40"
    assert (cached / large).read_bytes() == data
    assert frame.equals(load_comma2k19_segment(SEGMENT, recording=f"{ROUTE}--40"))
    assert not [p for p in home.rglob(".*")]


def test_a_cached_segment_refused_as_damaged_is_removed_and_fetched_again(tmp_path):
    url = _chunk(tmp_path / "mirror")
    home = tmp_path / "home"
    first = fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
    cached = home / "comma2k19" / ROUTE.replace("|", "--") / "40"
    file = cached / "processed_log" / "CAN" / "raw_can" / "t"
    file.write_bytes(file.read_bytes()[:100])
    with pytest.raises(ValueError, match="raw_can/t.*not a readable NumPy array.*removed from"):
        fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
    assert not cached.exists()
    again = fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
    assert again.equals(first)


def test_a_segment_the_loader_cannot_decode_stays_in_the_cache(tmp_path):
    """Not damaged, only not a Toyota (no steering frames): fetching it again would not help."""
    url = _chunk(tmp_path / "mirror")
    home = tmp_path / "home"
    fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
    cached = home / "comma2k19" / ROUTE.replace("|", "--") / "40"
    address = cached / "processed_log" / "CAN" / "raw_can" / "address"
    values = np.load(address)
    with open(address, "wb") as f:
        np.save(f, np.where(values == 0x260, 0x7FF, values))
    with pytest.raises(ValueError, match="no STEER_TORQUE_SENSOR frames"):
        fetch_comma2k19(segments=NAME, data_home=home, base_url=url, progress=False)
    assert cached.is_dir()


# --- errors that name what is wrong (item 13) --------------------------------------------------


@pytest.mark.parametrize(
    "location, reason",
    [
        ("/Chunk_1.zip", "too many redirects"),
        # aiohttp 3.9 names the location; older releases say only what they refuse
        (
            "file:///etc/passwd",
            "(redirected to file:///etc/passwd, which is not an http|Can redirect only to http)",
        ),
        (
            "ftp://example.org/Chunk_1.zip",
            "(redirected to ftp://example.org/Chunk_1.zip, which|Can redirect only to http)",
        ),
    ],
)
def test_redirects_that_cannot_be_followed_say_why(tmp_path, location, reason):
    with Server(tmp_path, redirects={"/Chunk_1.zip": location}) as server:
        url = server.url + "Chunk_1.zip"
        with pytest.raises(OSError, match=rf"Cannot download {re.escape(repr(url))}: {reason}"):
            fetch_comma2k19(segments=NAME, data_home=tmp_path / "h", base_url=server.url)


def test_a_missing_archive_says_so(tmp_path):
    with (
        Server(tmp_path) as server,
        pytest.raises(OSError, match="Chunk_1.zip': the server answered HTTP 404 Not Found"),
    ):
        fetch_comma2k19(segments=NAME, data_home=tmp_path / "h", base_url=server.url)
    with pytest.raises(OSError, match="Chunk_1.zip': .*No such file or directory"):
        fetch_comma2k19(segments=NAME, data_home=tmp_path / "h", base_url=tmp_path.as_uri())


def test_a_manifest_behind_a_redirect_loop_is_not_taken_for_a_missing_one(tmp_path):
    with (
        Server(tmp_path, redirects={"/SHA256SUMS": "/SHA256SUMS"}) as server,
        pytest.raises(OSError, match="SHA256SUMS': too many redirects"),
    ):
        read_manifest(server.url)


@pytest.mark.parametrize(
    "content, problem",
    [
        ("abc  Chunk_1.zip\n", r"Line 1 of the manifest .*SHA256SUMS'.*64 hexadecimal"),
        (f"{'0' * 64}\n", r"Line 1 of the manifest .*SHA256SUMS'.*not '<SHA-256> <file name>'"),
    ],
)
def test_a_bad_manifest_line_names_the_manifest_and_the_line(tmp_path, content, problem):
    (tmp_path / "SHA256SUMS").write_text(content)
    with pytest.raises(ValueError, match=problem):
        read_manifest(tmp_path.as_uri())


def test_a_manifest_that_is_not_text_is_named(tmp_path):
    (tmp_path / "SHA256SUMS").write_text("0" * 64 + "  Chunk_1.zip\n", encoding="utf-16")
    with pytest.raises(ValueError, match=r"manifest .*SHA256SUMS' is not UTF-8 text"):
        read_manifest(tmp_path.as_uri())


def test_a_member_placed_after_the_central_directory_is_named(tmp_path):
    """The central directory's offset of the last member is pointed past the directory."""
    _chunk(tmp_path / "mirror")
    archive = tmp_path / "mirror" / "Chunk_1.zip"
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as zf:
        last = zf.infolist()[-1]
        directory = zf.start_dir
    entry = data.rfind(b"PK\x01\x02", directory)  # the last member's central directory entry
    data[entry + 42 : entry + 46] = (len(data) + 1000).to_bytes(4, "little")
    archive.write_bytes(bytes(data))
    url = archive.parent.as_uri() + "/"
    pattern = rf"places the member {re.escape(repr(last.filename))} at byte \d+, outside"
    with pytest.raises(OSError, match=pattern):
        fetch_comma2k19(segments=NAME, data_home=tmp_path / "h", base_url=url)


def test_a_segment_number_of_5000_digits_is_not_a_segment(tmp_path):
    with pytest.raises(ValueError, match=r"is not a comma2k19 segment identifier") as info:
        fetch_comma2k19(segments=f"{ROUTE}/{'9' * 5000}", data_home=tmp_path)
    assert len(str(info.value)) < 300
    # in an archive, such a folder is no segment: its files are not unpacked
    url = _chunk(tmp_path / "mirror", [(f"../{'9' * 5000}/x", b"1", zipfile.ZIP_STORED)])
    with pytest.raises(ValueError, match="outside the target folder|in none of"):
        fetch_comma2k19(segments=f"{ROUTE}/41", data_home=tmp_path / "h", base_url=url)


@pytest.mark.parametrize(
    "relative, problem",
    [("processed_log/" + "x" * 300, "name too long"), ("processed_log/CAN/speed/t/inside", "")],
)
def test_members_that_cannot_be_written_name_member_and_archive(tmp_path, relative, problem):
    """A 300-character file name; a file where a folder must be (speed/t is a file)."""
    url = _chunk(tmp_path / "mirror", [(relative, b"1", zipfile.ZIP_STORED)])
    pattern = rf"Cannot unpack the member {re.escape(repr(_member(relative)))} of the archive "
    with pytest.raises(OSError, match=pattern + ".*" + problem) as info:
        fetch_comma2k19(segments=NAME, data_home=tmp_path / "h", base_url=url)
    assert "Chunk_1.zip" in str(info.value)
    assert _nothing_kept(tmp_path / "h")
