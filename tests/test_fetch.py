"""Offline tests of the download helpers and of fetch_comma2k19.

Archives are built at test time from the comma2k19 example segment and served from a file://
URL or from an HTTP server on 127.0.0.1; nothing here touches any other network.
"""

import hashlib
import http.server
import io
import tarfile
import threading
import warnings
import zipfile
from functools import partial
from pathlib import Path

import numpy as np
import pytest

from skhmmgmr.datasets import _download, clear_data_home, fetch_comma2k19, get_data_home
from skhmmgmr.datasets._download import download, extract, list_members, read_manifest

SEGMENT = Path("/work/shared/data/comma2k19/b0c9d2329ad1606b--2018-08-02--08-34-47/40")
ROUTE = "b0c9d2329ad1606b|2018-08-02--08-34-47"


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
    if not SEGMENT.is_dir():
        pytest.skip("comma2k19 example not present")
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


class _TruncatingHandler(_QuietHandler):
    """Announces the whole file, sends half of it, then hangs up."""

    def do_GET(self):
        path = Path(self.translate_path(self.path))
        if not path.is_file():
            self.send_error(404)
            return
        data = path.read_bytes()
        self.send_response(200)
        self.send_header("Content-Length", str(len(data)))
        self.end_headers()
        self.wfile.write(data[: len(data) // 2])
        self.wfile.flush()
        self.close_connection = True


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
    server, thread, requests = _serve(mirror[0], _QuietHandler)
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}/", requests
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)


def test_fetch_from_file_url(mirror, tmp_path):
    folder, digest = mirror
    home = tmp_path / "home"
    frame = fetch_comma2k19(
        data_home=home, base_url=folder.as_uri() + "/", checksums={"Chunk_1.zip": digest}
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


def test_fetch_over_http_with_manifest_then_from_cache(http_mirror, tmp_path):
    url, requests = http_mirror
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = fetch_comma2k19(segments=f"{ROUTE}/41", data_home=tmp_path, base_url=url)
    assert (frame["recording"] == f"{ROUTE}--41").all()
    assert sorted(requests) == ["/Chunk_1.zip", "/SHA256SUMS"]

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
            checksums={"Chunk_1.zip": "0" * 64},
        )
    assert _files(tmp_path) == []


def test_truncated_download_keeps_nothing(mirror, tmp_path):
    server, thread, _ = _serve(mirror[0], _TruncatingHandler)
    try:
        url = f"http://127.0.0.1:{server.server_address[1]}/"
        with pytest.raises(OSError, match="stopped after"):
            download(url + "Chunk_1.zip", tmp_path / "Chunk_1.zip", timeout=10)
    finally:
        server.shutdown()
        server.server_close()
        thread.join(timeout=5)
    assert _files(tmp_path) == []


def test_interrupted_download_keeps_nothing(tmp_path, monkeypatch):
    class Response(io.BytesIO):
        headers = {}

        def read(self, size=-1):
            if self.tell() > 0:
                raise KeyboardInterrupt
            return super().read(10)

    monkeypatch.setattr(_download, "urlopen", lambda url, timeout: Response(b"x" * 100))
    with pytest.raises(KeyboardInterrupt):
        fetch_comma2k19(data_home=tmp_path, base_url="http://127.0.0.1:9/", checksums={})
    assert _files(tmp_path) == []


def test_unverified_download_warns_with_digest(mirror, tmp_path):
    folder, digest = mirror
    bare = tmp_path / "bare"
    bare.mkdir()
    (bare / "Chunk_1.zip").symlink_to(folder / "Chunk_1.zip")
    with pytest.warns(UserWarning, match=digest):
        fetch_comma2k19(segments=f"{ROUTE}/40", data_home=tmp_path / "home", base_url=bare.as_uri())
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
