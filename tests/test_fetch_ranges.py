"""Offline tests of reading comma2k19 segments straight out of a remote archive (issue #26).

The archive is built here from the example segment (as segments 40 and 41 of its route), each
segment followed by a 50 MB stored ``video.hevc`` of random bytes, as in the real chunks. It is
served from a file:// URL and by a local HTTP server (``_http_server.py``) that honours Range
headers and counts the bytes it sends.
"""

import hashlib
import importlib.util
import re
import sys
import warnings
import zipfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from _comma2k19_data import ROUTE, SEGMENT
from _http_server import Server

from skhmmgmr.datasets import _remote as remote
from skhmmgmr.datasets import fetch_comma2k19, load_comma2k19_segment, scan_comma2k19
from skhmmgmr.datasets._comma2k19 import _fetch
from skhmmgmr.datasets._download import file_url
from skhmmgmr.datasets._remote import hub_sha256

try:
    import fcntl
except ImportError:  # Windows
    fcntl = None

pytest.importorskip("fsspec")
pytest.importorskip("aiohttp")

VIDEO_MB = 50
CACHED = ROUTE.replace("|", "--")
HUB = Path("datasets", "commaai", "comma2k19", "resolve", "main")


def _member(number, relative):
    return f"Chunk_1/{ROUTE}/{number}/{relative}"


@pytest.fixture(scope="module")
def mirror(tmp_path_factory):
    """(folder with Chunk_1.zip, its SHA-256); the folder also has the Hub's URL layout."""
    folder = tmp_path_factory.mktemp("mirror")
    archive = folder / "Chunk_1.zip"
    block = np.random.default_rng(0).bytes(1 << 20)
    with zipfile.ZipFile(archive, "w", compression=zipfile.ZIP_STORED) as zf:
        for number in (40, 41):
            for file in sorted(p for p in SEGMENT.rglob("*") if p.is_file()):
                zf.write(file, _member(number, file.relative_to(SEGMENT).as_posix()))
            with zf.open(_member(number, "video.hevc"), "w") as video:
                for _ in range(VIDEO_MB):
                    video.write(block)
    (folder / HUB).mkdir(parents=True)
    (folder / HUB / "Chunk_1.zip").symlink_to(archive)
    digest = hashlib.sha256(archive.read_bytes()).hexdigest()
    return folder, digest


@pytest.fixture
def server(mirror):
    with Server(mirror[0]) as running:
        yield running


def _cached_files(home):
    return sorted(str(p.relative_to(home)) for p in Path(home).rglob("*") if p.is_file())


def _segment_files(number):
    return sorted(
        f"comma2k19/{CACHED}/{number}/{p.relative_to(SEGMENT).as_posix()}"
        for p in SEGMENT.rglob("*")
        if p.is_file()
    )


def test_range_read_over_http_reads_a_small_fraction(mirror, server, tmp_path):
    size = (mirror[0] / "Chunk_1.zip").stat().st_size
    frame = fetch_comma2k19(segments=f"{ROUTE}/41", data_home=tmp_path, base_url=server.url)
    expected = load_comma2k19_segment(SEGMENT, recording=f"{ROUTE}--41")
    assert frame.equals(expected)
    assert frame.attrs == expected.attrs
    members = sum(p.stat().st_size for p in SEGMENT.rglob("*") if p.is_file())
    # the segment's files, their headers and the central directory; not the video
    assert members < server.sent < members + 64_000
    assert server.sent < 0.05 * size
    assert all(rng for method, _, rng in server.log if method == "GET")
    assert len(server.log) <= 6
    # only the segment's folders are kept: no archive, no video, no temporary file
    assert _cached_files(tmp_path) == sorted(
        ["comma2k19/Chunk_1.segments.txt", *_segment_files(41)]
    )


def test_range_read_from_file_url_equals_the_loader(mirror, tmp_path):
    base_url = mirror[0].as_uri() + "/"
    frame = fetch_comma2k19(segments=[f"{ROUTE}/40"], data_home=tmp_path, base_url=base_url)
    assert frame.equals(load_comma2k19_segment(SEGMENT, recording=f"{ROUTE}--40"))
    assert not list(tmp_path.rglob("video.hevc"))
    # the next segment comes from the same archive; the first is read from the cache
    both = fetch_comma2k19(
        segments=[f"{ROUTE}/40", f"{ROUTE}/41"], data_home=tmp_path, base_url=base_url
    )
    assert list(both["recording"].unique()) == [f"{ROUTE}--40", f"{ROUTE}--41"]


def _damaged_copy(mirror, folder, name):
    data = bytearray((mirror[0] / "Chunk_1.zip").read_bytes())
    with zipfile.ZipFile(mirror[0] / "Chunk_1.zip") as zf:
        info = zf.getinfo(name)
    data[info.header_offset + 30 + len(info.filename.encode()) + len(info.extra) + 500] ^= 0xFF
    folder.mkdir()
    (folder / "Chunk_1.zip").write_bytes(bytes(data))


def test_crc_mismatch_names_member_and_url_and_keeps_nothing(mirror, tmp_path):
    name = _member(41, "processed_log/CAN/raw_can/data")
    _damaged_copy(mirror, tmp_path / "bad", name)
    home = tmp_path / "home"
    with Server(tmp_path / "bad") as server:
        url = server.url + "Chunk_1.zip"
        with pytest.raises(OSError, match=f"{re.escape(repr(name))}.*{re.escape(repr(url))}.*CRC"):
            fetch_comma2k19(segments=f"{ROUTE}/41", data_home=home, base_url=server.url)
        assert _cached_files(home) == []
        assert not [p for p in home.rglob("*") if p.name.startswith(".")]
        # the intact segment of the same archive is read
        frame = fetch_comma2k19(segments=f"{ROUTE}/40", data_home=home, base_url=server.url)
    assert (frame["recording"] == f"{ROUTE}--40").all()


def test_interrupted_archive_download_resumes_with_a_range_request(mirror, server, tmp_path):
    folder, digest = mirror
    size = (folder / "Chunk_1.zip").stat().st_size
    part = tmp_path / "comma2k19" / ".Chunk_1.zip.part"
    options = {
        "segments": f"{ROUTE}/40",
        "data_home": tmp_path,
        "base_url": server.url,
        "method": "archive",
        "checksums": {"Chunk_1.zip": digest},
        "progress": False,
    }
    server.cut_after(40 << 20)
    with pytest.raises(OSError, match=r"Chunk_1\.zip.*first 33554432 of .* kept.*resume"):
        fetch_comma2k19(**options)
    assert part.stat().st_size == 32 << 20  # two whole blocks of 16 MiB
    assert not (tmp_path / "comma2k19" / "Chunk_1.zip").exists()
    server.reset()
    frame = fetch_comma2k19(**options)
    assert frame.equals(load_comma2k19_segment(SEGMENT, recording=f"{ROUTE}--40"))
    ranges = [rng for method, _, rng in server.log if method == "GET"]
    assert ranges[0].startswith(f"bytes={32 << 20}-")
    assert server.sent == size - (32 << 20)
    assert not part.exists()
    assert (tmp_path / "comma2k19" / "Chunk_1.zip").read_bytes() == (
        folder / "Chunk_1.zip"
    ).read_bytes()


def test_ctrl_c_keeps_the_part_and_the_next_call_resumes(mirror, tmp_path, monkeypatch):
    folder, digest = mirror
    options = {
        "data_home": tmp_path,
        "base_url": folder.as_uri(),
        "method": "archive",
        "checksums": {"Chunk_1.zip": digest},
    }

    class Interrupted(remote.tqdm):
        def update(self, n=1):
            super().update(n)
            raise KeyboardInterrupt

    monkeypatch.setattr(remote, "tqdm", Interrupted)
    with pytest.raises(KeyboardInterrupt):
        fetch_comma2k19(**options)
    assert (tmp_path / "comma2k19" / ".Chunk_1.zip.part").stat().st_size == 16 << 20
    monkeypatch.undo()
    assert fetch_comma2k19(**options)["recording"].nunique() == 2
    assert _cached_files(tmp_path / "comma2k19")[:2] == ["Chunk_1.segments.txt", "Chunk_1.zip"]


@pytest.mark.skipif(fcntl is None, reason="needs POSIX file locks")
def test_a_part_another_download_writes_is_left_alone(mirror, tmp_path):
    cache = tmp_path / "comma2k19"
    cache.mkdir()
    part = cache / ".Chunk_1.zip.part"
    with open(part, "wb") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX)
        with pytest.raises(OSError, match="being written by another download"):
            fetch_comma2k19(
                data_home=tmp_path, base_url=mirror[0].as_uri(), method="archive", checksums={}
            )
    assert part.exists()


@pytest.fixture
def hub_api(monkeypatch):
    """The Hub's API call replaced by one answering ``hub_api.sha256``; ``hub_api.calls``."""
    hub = pytest.importorskip("huggingface_hub")
    api = SimpleNamespace(sha256=None, calls=[])

    def get_paths_info(self, repo_id, paths, *, repo_type=None, revision=None, **kwargs):
        api.calls.append((self.endpoint, repo_id, paths, repo_type, revision))
        # as the Hub's API answers for an LFS file
        lfs = {"size": 1, "oid": api.sha256, "pointerSize": 134}
        return [hub.hf_api.RepoFile(path=paths[0], size=1, oid="0" * 40, lfs=lfs)]

    monkeypatch.setattr(hub.HfApi, "get_paths_info", get_paths_info)
    return api


def test_archive_from_the_hub_is_verified_with_its_published_sha256(
    mirror, server, tmp_path, hub_api
):
    base_url = server.url + HUB.as_posix() + "/"
    hub_api.sha256 = mirror[1]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = fetch_comma2k19(data_home=tmp_path / "a", base_url=base_url, method="archive")
    assert frame["recording"].nunique() == 2
    assert hub_api.calls == [
        (server.url.rstrip("/"), "commaai/comma2k19", ["Chunk_1.zip"], "dataset", "main")
    ]
    assert not any(path.endswith("SHA256SUMS") for _, path, _ in server.log)
    hub_api.sha256 = "0" * 64
    with pytest.raises(OSError, match="Checksum mismatch"):
        fetch_comma2k19(data_home=tmp_path / "b", base_url=base_url, method="archive")
    assert _cached_files(tmp_path / "b") == []


def test_hub_urls_are_recognised(hub_api):
    hub_api.sha256 = "ab" * 32
    assert hub_sha256("http://127.0.0.1:9/data/Chunk_1.zip") is None
    assert (
        hub_sha256("https://huggingface.co/datasets/a/b/resolve/v1.0/x/Chunk_2.zip")
        == hub_api.sha256
    )
    assert hub_sha256("hf://datasets/a/b@refs%2Fpr%2F1/Chunk_2.zip") == hub_api.sha256
    assert [(c[0], c[2], c[4]) for c in hub_api.calls] == [
        ("https://huggingface.co", ["x/Chunk_2.zip"], "v1.0"),
        (hub_api.calls[1][0], ["Chunk_2.zip"], "refs/pr/1"),
    ]


def test_scan_reads_the_can_logs_only_and_feeds_fetch(mirror, server, tmp_path):
    pytest.importorskip("cantools")
    pytest.importorskip("opendbc")
    scan = scan_comma2k19(chunks=1, base_url=server.url, progress=False)
    can = sum(
        p.stat().st_size
        for folder in ("raw_can", "speed")
        for p in (SEGMENT / "processed_log" / "CAN" / folder).iterdir()
    )
    assert 2 * can < server.sent < 2 * can + 64_000
    assert list(scan["segment"]) == [f"{ROUTE}--40", f"{ROUTE}--41"]
    assert list(scan["problem"]) == ["", ""]
    frame = load_comma2k19_segment(SEGMENT, engagement=True)
    alone = (frame["openpilot_steer_request"] == 0) & (frame["eps_lka_active"] == 0)
    row = scan.iloc[0]
    assert row["duration_s"] == len(frame) / 20
    assert row["manual_s"] == alone.sum() / 20
    assert 0 < row["longest_manual_s"] <= row["manual_s"]
    assert row["engaged_s"] == frame["cruise_active"].sum() / 20
    assert row["pressed_s"] == (frame["driver_torque"].abs() > 100).sum() / 20
    assert (row["speed_min"], row["speed_max"]) == (frame["speed"].min(), frame["speed"].max())
    spans = load_comma2k19_segment(SEGMENT, steering="driver", min_span=0)
    longest = spans.groupby("recording").size().max() / 20
    assert row["longest_manual_s"] == longest
    # the scan picks what fetch_comma2k19 reads
    picked = scan.loc[scan.manual_s > 5, "segment"]
    fetched = fetch_comma2k19(segments=picked, data_home=tmp_path, base_url=server.url)
    assert list(fetched["recording"].unique()) == list(picked)


def test_a_server_ignoring_ranges_is_refused(mirror, tmp_path):
    with Server(mirror[0], ranges=False) as server:
        with pytest.raises(OSError, match=r"Chunk_1\.zip'.*range requests"):
            fetch_comma2k19(segments=f"{ROUTE}/40", data_home=tmp_path, base_url=server.url)
        assert server.sent < 4 << 20
    assert _cached_files(tmp_path) == []


def test_without_the_fetch_extra_the_error_names_it(mirror, tmp_path, monkeypatch):
    base_url = mirror[0].as_uri()
    fetch_comma2k19(segments=f"{ROUTE}/40", data_home=tmp_path, base_url=base_url)
    monkeypatch.setitem(sys.modules, "fsspec", None)
    # what is in the cache loads without it
    fetch_comma2k19(segments=f"{ROUTE}/40", data_home=tmp_path, base_url=base_url)
    with pytest.raises(ImportError, match=re.escape("pip install 'skhmmgmr[fetch]'")):
        fetch_comma2k19(segments=f"{ROUTE}/41", data_home=tmp_path, base_url=base_url)
    if importlib.util.find_spec("cantools") and importlib.util.find_spec("opendbc"):
        with pytest.raises(ImportError, match=re.escape("skhmmgmr[fetch]")):
            scan_comma2k19(chunks=1, base_url=base_url)


def test_fetch_reads_a_chunk_whole_in_batches(mirror, tmp_path, monkeypatch):
    monkeypatch.setattr(_fetch, "_BATCH", 1)
    frame = fetch_comma2k19(data_home=tmp_path, base_url=mirror[0].as_uri(), progress=False)
    assert frame["recording"].nunique() == 2
    assert not list(tmp_path.rglob("video.hevc"))


def test_hf_urls_open_the_hubs_file_system():
    pytest.importorskip("huggingface_hub")
    base_url = "hf://datasets/commaai/comma2k19"
    url = file_url(base_url, "Chunk_1.zip")
    assert url == "hf://datasets/commaai/comma2k19/Chunk_1.zip"
    fs, path = remote.remote_fs(url, timeout=5)
    assert type(fs).__name__ == "HfFileSystem"
    assert path == "datasets/commaai/comma2k19/Chunk_1.zip"
