"""Offline tests of the download helpers and of fetch_comma2k19.

Archives are built at test time from the comma2k19 example segment and served from a file://
URL or from an HTTP server on 127.0.0.1; nothing here touches any other network. Range reads,
resumed downloads and the scan are in test_fetch_ranges.py.
"""

import hashlib
import http.server
import io
import os
import re
import socket
import tarfile
import threading
import time
import warnings
import zipfile
from functools import partial
from pathlib import Path

import numpy as np
import pytest

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

from _comma2k19_data import ROUTE, SEGMENT
from _http_server import Server

from skhmmgmr.datasets import clear_data_home, fetch_comma2k19, get_data_home
from skhmmgmr.datasets._download import extract, list_members
from skhmmgmr.datasets._remote import read_manifest


def _files(folder):
    return sorted(p for p in Path(folder).rglob("*") if p.is_file())


def _write_zip(path, members):
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_STORED) as zf:
        for name, data in members:
            zf.writestr(name, data)


def _segment_members(number):
    for file in _files(SEGMENT):
        relative = file.relative_to(SEGMENT).as_posix()
        yield f"Chunk_1/{ROUTE}/{number}/{relative}", file.read_bytes()


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    """A folder with Chunk_1.zip (segments 40 and 41 of the route) and its SHA256SUMS."""
    folder = tmp_path_factory.mktemp("mirror")
    _write_zip(folder / "Chunk_1.zip", [*_segment_members(40), *_segment_members(41)])
    digest = hashlib.sha256((folder / "Chunk_1.zip").read_bytes()).hexdigest()
    (folder / "SHA256SUMS").write_text(f"{digest}  Chunk_1.zip\n")
    return folder, digest


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    requests = []

    def log_message(self, *args):
        pass

    def do_GET(self):
        type(self).requests.append(self.path)
        super().do_GET()


def _serve(folder, handler):
    handler = type("Handler", (handler,), {"requests": []})
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", 0), partial(handler, directory=str(folder))
    )
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05})
    thread.daemon = True
    thread.start()
    return server, thread, handler.requests


@pytest.fixture
def http_mirror(mirror):
    with Server(mirror[0]) as server:
        yield server.url, server.log


def test_fetch_from_file_url(mirror, tmp_path):
    folder, digest = mirror
    home = tmp_path / "home"
    frame = fetch_comma2k19(
        data_home=home,
        base_url=folder.as_uri() + "/",
        method="archive",
        checksums={"Chunk_1.zip": digest},
    )
    names = [f"{ROUTE}--40", f"{ROUTE}--41"]
    assert list(frame["recording"].unique()) == names
    assert set(frame.attrs["time_origin"]) == set(names)
    assert frame.attrs["units"]["driver_torque"] == "raw sensor units"
    first, second = (frame.loc[frame["recording"] == n].iloc[:, 4:] for n in names)
    np.testing.assert_array_equal(first.to_numpy(dtype=float), second.to_numpy(dtype=float))
    cache = home / "comma2k19"
    assert (cache / "Chunk_1.zip").is_file()
    assert (cache / "b0c9d2329ad1606b--2018-08-02--08-34-47" / "41" / "processed_log").is_dir()
    assert not [p for p in cache.rglob(".*")]


def test_fetch_keeps_the_driver_spans_of_each_segment(mirror, tmp_path):
    pytest.importorskip("cantools")
    pytest.importorskip("opendbc")
    folder, digest = mirror
    frame = fetch_comma2k19(
        data_home=tmp_path,
        base_url=folder.as_uri() + "/",
        checksums={"Chunk_1.zip": digest},
        engagement=True,
        steering="driver",
    )
    names = [f"{ROUTE}--40/span0", f"{ROUTE}--41/span0"]
    assert list(frame["recording"].unique()) == names
    assert set(frame.attrs["time_origin"]) == set(names)
    assert (frame[["openpilot_steer_request", "eps_lka_active"]] == 0).all().all()


def test_fetch_over_http_with_manifest_then_from_cache(http_mirror, tmp_path):
    url, requests = http_mirror
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = fetch_comma2k19(
            segments=f"{ROUTE}/41", data_home=tmp_path, base_url=url, method="archive"
        )
    assert (frame["recording"] == f"{ROUTE}--41").all()
    assert sorted({path for _, path, _ in requests}) == ["/Chunk_1.zip", "/SHA256SUMS"]

    n_requests = len(requests)
    again = fetch_comma2k19(
        segments=["b0c9d2329ad1606b--2018-08-02--08-34-47--41"],
        data_home=tmp_path,
        base_url=url,
        download_if_missing=False,
    )
    assert again.equals(frame)
    # Another segment of the cached archive is unpacked without any download.
    other = fetch_comma2k19(
        segments=f"{ROUTE}/40", data_home=tmp_path, base_url=url, download_if_missing=False
    )
    assert (other["recording"] == f"{ROUTE}--40").all()
    assert len(requests) == n_requests


def test_download_if_missing_false_before_first_fetch(mirror, tmp_path):
    with pytest.raises(OSError, match="download_if_missing=False"):
        fetch_comma2k19(
            segments=f"{ROUTE}/40",
            data_home=tmp_path,
            base_url=mirror[0].as_uri() + "/",
            download_if_missing=False,
        )
    assert _files(tmp_path) == []


def test_cache_without_archive_works_offline(mirror, tmp_path):
    folder, digest = mirror
    fetch_comma2k19(
        data_home=tmp_path,
        base_url=folder.as_uri() + "/",
        checksums={"Chunk_1.zip": digest},
        keep_archive=False,
    )
    assert not (tmp_path / "comma2k19" / "Chunk_1.zip").exists()
    frame = fetch_comma2k19(
        data_home=tmp_path, base_url="http://127.0.0.1:9/", download_if_missing=False
    )
    assert frame["recording"].nunique() == 2


def test_checksum_mismatch_keeps_nothing(mirror, tmp_path):
    with pytest.raises(OSError, match="Checksum mismatch"):
        fetch_comma2k19(
            data_home=tmp_path,
            base_url=mirror[0].as_uri() + "/",
            method="archive",
            checksums={"Chunk_1.zip": "0" * 64},
        )
    assert _files(tmp_path) == []


def test_unverified_download_warns_with_digest(mirror, tmp_path):
    folder, digest = mirror
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "Chunk_1.zip").symlink_to(folder / "Chunk_1.zip")
    with pytest.warns(UserWarning, match=digest):
        fetch_comma2k19(
            segments=f"{ROUTE}/40",
            data_home=tmp_path / "home",
            base_url=bare.as_uri(),
            method="archive",
        )
    assert read_manifest(bare.as_uri()) is None


def test_unknown_segment_is_named(mirror, tmp_path):
    folder, digest = mirror
    with pytest.raises(ValueError, match=r"b0c9d2329ad1606b\|2018-08-02--08-34-47--7 "):
        fetch_comma2k19(
            segments=[f"{ROUTE}/40", f"{ROUTE}/7"],
            data_home=tmp_path,
            base_url=folder.as_uri(),
            checksums={"Chunk_1.zip": digest},
        )


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"segments": "not-a-segment"}, "not a comma2k19 segment"),
        ({"chunks": 11}, "chunks"),
        ({"chunks": []}, "chunks"),
        ({"sampling_rate": -1}, "sampling_rate"),
        ({"base_url": "ftp://127.0.0.1/"}, "only http"),
        ({"method": "torrent"}, "method"),
    ],
)
def test_invalid_arguments(kwargs, match, tmp_path):
    with pytest.raises(ValueError, match=match):
        fetch_comma2k19(data_home=tmp_path, checksums={}, **kwargs)


@pytest.mark.filterwarnings("ignore:No SHA-256 checksum")
def test_path_traversal_is_refused(tmp_path):
    folder = tmp_path / "evil_mirror"
    folder.mkdir()
    _write_zip(
        folder / "Chunk_1.zip",
        [(f"Chunk_1/{ROUTE}/40/../../../../escaped.txt", b"x"), (f"Chunk_1/{ROUTE}/40/a", b"")],
    )
    with pytest.raises(ValueError, match="outside the target folder"):
        fetch_comma2k19(data_home=tmp_path / "home", base_url=folder.as_uri(), checksums={})
    assert not list(tmp_path.rglob("escaped.txt"))
    assert not (tmp_path / "home" / "comma2k19" / "b0c9d2329ad1606b--2018-08-02--08-34-47").exists()


def _tar(path, entries):
    with tarfile.open(path, "w:gz") as tf:
        for name, data, kind in entries:
            info = tarfile.TarInfo(name)
            info.type = kind
            if kind == tarfile.SYMTYPE:
                info.linkname = "/etc/passwd"
                tf.addfile(info)
            else:
                info.size = len(data)
                tf.addfile(info, io.BytesIO(data))


def test_tar_archives_are_listed_and_unpacked_safely(tmp_path):
    archive = tmp_path / "data.tar.gz"
    _tar(archive, [("top/a.txt", b"alpha", tarfile.REGTYPE), ("top/link", b"", tarfile.SYMTYPE)])
    assert list_members(archive) == [("top", "a.txt")]
    out = tmp_path / "out"
    extract(archive, lambda parts: out.joinpath(*parts))
    assert (out / "top" / "a.txt").read_bytes() == b"alpha"
    assert not (out / "top" / "link").exists()

    evil = tmp_path / "evil.tar.gz"
    _tar(evil, [("/abs/b.txt", b"beta", tarfile.REGTYPE)])
    with pytest.raises(ValueError, match="outside"):
        list_members(evil)
    with pytest.raises(ValueError, match="outside"):
        extract(evil, lambda parts: out.joinpath(*parts))
    not_an_archive = tmp_path / "plain.zip"
    not_an_archive.write_bytes(b"plain text")
    with pytest.raises(ValueError, match="neither a zip nor a tar"):
        list_members(not_an_archive)


def test_read_manifest_parses_sha256sum_format(tmp_path):
    digest = "ab" * 32
    (tmp_path / "SHA256SUMS").write_text(f"# comment\n{digest.upper()} *Chunk_2.zip\n\n")
    assert read_manifest(tmp_path.as_uri()) == {"Chunk_2.zip": digest}
    (tmp_path / "SHA256SUMS").write_text("nonsense\n")
    with pytest.raises(ValueError, match="malformed"):
        read_manifest(tmp_path.as_uri())


def test_data_home_env_variable_and_clearing(tmp_path, monkeypatch):
    monkeypatch.setenv("SKHMMGMR_DATA", str(tmp_path / "from_env"))
    assert get_data_home() == str(tmp_path / "from_env")
    assert (tmp_path / "from_env").is_dir()
    assert get_data_home(tmp_path / "explicit") == str(tmp_path / "explicit")
    monkeypatch.delenv("SKHMMGMR_DATA")
    monkeypatch.setenv("HOME", str(tmp_path))
    assert get_data_home() == str(tmp_path / "skhmmgmr_data")
    (tmp_path / "skhmmgmr_data" / "file").write_text("cached")
    clear_data_home()
    assert not (tmp_path / "skhmmgmr_data").exists()


# --- interrupted, damaged and failed downloads (issue #17) ---------------------------------


def _serving(folder, handler):
    """Context of an HTTP server on 127.0.0.1 for ``folder``; yields its base URL."""

    class _Context:
        def __enter__(self):
            self.server, self.thread, _ = _serve(folder, handler)
            return f"http://127.0.0.1:{self.server.server_address[1]}/"

        def __exit__(self, *exc):
            self.server.shutdown()
            self.server.server_close()
            self.thread.join(timeout=5)

    return _Context()


class _ChunkedCutHandler(_QuietHandler):
    """Sends half of the file in chunked encoding, then hangs up without the last chunk."""

    protocol_version = "HTTP/1.1"

    def do_GET(self):
        data = Path(self.translate_path(self.path)).read_bytes()[:1000]
        self.send_response(200)
        self.send_header("Transfer-Encoding", "chunked")
        self.end_headers()
        self.wfile.write(b"%x\r\n%s\r\n" % (len(data), data))
        self.wfile.flush()
        self.close_connection = True


class _UnsizedCutHandler(_QuietHandler):
    """Sends half of the file without a Content-Length header, then hangs up."""

    def do_GET(self):
        data = Path(self.translate_path(self.path)).read_bytes()
        self.send_response(200)
        self.end_headers()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        self.close_connection = True


class _SlowHandler(_QuietHandler):
    def do_GET(self):
        time.sleep(1.0)
        super().do_GET()


class _FailingHandler(_QuietHandler):
    def do_GET(self):
        self.send_error(503)


def _no_kept_file(home):
    cache = Path(home) / "comma2k19"
    return not cache.exists() or [p.name for p in cache.iterdir()] == []


@pytest.mark.parametrize("method", ["range", "archive"])
@pytest.mark.parametrize(
    "handler, problem",
    [
        (_ChunkedCutHandler, "payload is not completed|range requests"),
        (_UnsizedCutHandler, "connection was cut|range requests"),
    ],
)
def test_cut_download_is_never_kept(mirror, tmp_path, handler, problem, method):
    # Both servers ignore Range headers and hang up early: nothing of it is kept (a cut
    # before the first complete block leaves no part to resume).
    with (
        _serving(mirror[0], handler) as url,
        pytest.raises(OSError, match=re.escape(repr(url + "Chunk_1.zip")) + f".*({problem})"),
    ):
        fetch_comma2k19(data_home=tmp_path, base_url=url, method=method, checksums={}, timeout=10)
    assert _no_kept_file(tmp_path)


def _damage(data, name):
    """Flip one byte of the data of the archive member ``name``, leaving its headers intact."""
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        info = zf.getinfo(name)
    start = info.header_offset + 30 + len(info.filename.encode()) + len(info.extra)
    data = bytearray(data)
    data[start] ^= 0xFF
    return bytes(data)


@pytest.mark.parametrize(
    "content, match",
    [
        (lambda data: b"<html>Not the archive</html>", "not a readable zip archive"),
        (lambda data: data[: len(data) - 10], "not a readable zip archive"),
        (lambda data: _damage(data, f"Chunk_1/{ROUTE}/41/processed_log/CAN/speed/t"), "CRC"),
    ],
    ids=["garbage", "cut", "bad-crc"],
)
@pytest.mark.parametrize("method", ["range", "archive"])
def test_damaged_archive_without_checksum_is_refused(mirror, tmp_path, content, match, method):
    bad = tmp_path / "bad_mirror"
    bad.mkdir()
    (bad / "Chunk_1.zip").write_bytes(content((mirror[0] / "Chunk_1.zip").read_bytes()))
    url = bad.as_uri() + "/Chunk_1.zip"
    with pytest.raises(OSError, match=f"{re.escape(repr(url))}.*{match}"):
        fetch_comma2k19(
            data_home=tmp_path / "home", base_url=bad.as_uri(), method=method, checksums={}
        )
    assert _no_kept_file(tmp_path / "home")


def test_damaged_cached_archive_is_downloaded_again(mirror, tmp_path):
    folder, digest = mirror
    cache = tmp_path / "comma2k19"
    cache.mkdir()
    (cache / "Chunk_1.zip").write_bytes(b"PK\x03\x04 cut by an earlier version")
    with pytest.raises(OSError, match=r"Chunk_1\.zip.*not a readable zip archive"):
        fetch_comma2k19(data_home=tmp_path, base_url=folder.as_uri(), download_if_missing=False)
    with pytest.warns(UserWarning, match=r"Chunk_1\.zip.*downloaded again"):
        frame = fetch_comma2k19(
            data_home=tmp_path,
            base_url=folder.as_uri(),
            method="archive",
            checksums={"Chunk_1.zip": digest},
        )
    assert frame["recording"].nunique() == 2
    assert (cache / "Chunk_1.zip").read_bytes() == (folder / "Chunk_1.zip").read_bytes()


def _part(folder, target, tag, age):
    path = folder / f".{target}.{tag}.part"
    path.write_bytes(b"x" * 1000)
    os.utime(path, (time.time() - age, time.time() - age))
    return path


@pytest.mark.skipif(fcntl is None, reason="needs POSIX file locks")
def test_stale_part_files_are_removed_but_live_ones_kept(mirror, tmp_path):
    folder, digest = mirror
    cache = tmp_path / "comma2k19"
    cache.mkdir()
    stale = _part(cache, "Chunk_1.zip", "k1ll3d_0", age=3600)
    other_target = _part(cache, "Chunk_2.zip", "k1ll3d_0", age=3600)
    live = _part(cache, "Chunk_1.zip", "l1ve_000", age=3600)
    with open(live, "rb") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        fetch_comma2k19(
            segments=f"{ROUTE}/40",
            data_home=tmp_path,
            base_url=folder.as_uri(),
            checksums={"Chunk_1.zip": digest},
        )
        assert not stale.exists()
        assert other_target.exists() and live.exists()
    # A later call finds the archive in the cache and still removes dead downloads.
    stale = _part(cache, "Chunk_1.zip", "k1ll3d_1", age=3600)
    fetch_comma2k19(
        segments=f"{ROUTE}/41", data_home=tmp_path, base_url=folder.as_uri(), checksums={}
    )
    assert not stale.exists() and not live.exists()


def _closed_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_network_errors_name_the_url(mirror, tmp_path):
    url = f"http://127.0.0.1:{_closed_port()}/"
    with pytest.raises(OSError, match=re.escape(repr(url + "Chunk_1.zip"))):
        fetch_comma2k19(data_home=tmp_path, base_url=url, checksums={})
    with pytest.raises(OSError, match=re.escape(repr(url + "SHA256SUMS"))):
        fetch_comma2k19(data_home=tmp_path, base_url=url, method="archive")
    with _serving(mirror[0], _FailingHandler) as url:
        with pytest.raises(OSError, match=re.escape(repr(url + "SHA256SUMS")) + ".*503"):
            fetch_comma2k19(data_home=tmp_path, base_url=url, method="archive")
        for method in ("range", "archive"):
            with pytest.raises(OSError, match=re.escape(repr(url + "Chunk_1.zip")) + ".*503"):
                fetch_comma2k19(data_home=tmp_path, base_url=url, method=method, checksums={})
    with (
        _serving(mirror[0], _SlowHandler) as url,
        pytest.raises(OSError, match=re.escape(repr(url + "Chunk_1.zip")) + ".*timed out"),
    ):
        fetch_comma2k19(data_home=tmp_path, base_url=url, checksums={}, timeout=0.2)
    with pytest.raises(OSError, match=r"Chunk_3\.zip'.*No such file"):
        fetch_comma2k19(data_home=tmp_path, base_url=mirror[0].as_uri(), chunks=3, checksums={})
    assert _no_kept_file(tmp_path)
