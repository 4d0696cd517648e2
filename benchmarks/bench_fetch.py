"""Range reads of comma2k19 against a local HTTP server: bytes and wall time per segment.

Builds a chunk-like archive of ``--segments`` copies of the comma2k19 sample that ships with the
package (written out as a segment folder), each followed by a stored ``video.hevc`` of
``--video-mb`` random MB as in the real chunks, serves it from 127.0.0.1 with the tests'
Range-honouring server (``tests/_http_server.py``, which counts the bytes it sends) and times:

- ``fetch_comma2k19(segments=<one>)`` with range reads (fresh cache each repeat);
- the same segment with ``method="archive"`` (the whole archive downloaded, verified, unpacked);
- ``scan_comma2k19`` over every segment (needs ``skhmmgmr[can]``).

A local server has no network latency nor bandwidth limit: the times are the package's own
cost (requests, CRC checks, unpacking, decoding), a lower bound of what the Hub gives. Needs
``skhmmgmr[fetch]``.

    python benchmarks/bench_fetch.py --segments 16 --video-mb 40
"""

import argparse
import json
import statistics
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _comma2k19_data import ROUTE, SEGMENT
from _http_server import Server

from skhmmgmr.datasets import fetch_comma2k19, scan_comma2k19


def build(folder, n_segments, video_mb):
    block = np.random.default_rng(0).bytes(1 << 20)
    files = sorted(p for p in SEGMENT.rglob("*") if p.is_file())
    with zipfile.ZipFile(folder / "Chunk_1.zip", "w", compression=zipfile.ZIP_STORED) as zf:
        for number in range(n_segments):
            for file in files:
                relative = file.relative_to(SEGMENT).as_posix()
                zf.write(file, f"Chunk_1/{ROUTE}/{number}/{relative}")
            with zf.open(f"Chunk_1/{ROUTE}/{number}/video.hevc", "w") as video:
                for _ in range(video_mb):
                    video.write(block)
    return (folder / "Chunk_1.zip").stat().st_size


def timed(server, call, repeats):
    times, sent, requests = [], [], []
    for _ in range(repeats):
        server.reset()
        with tempfile.TemporaryDirectory() as home:
            start = time.perf_counter()
            call(home)
            times.append(time.perf_counter() - start)
        sent.append(server.sent)
        requests.append(len(server.log))
    return {
        "seconds_median": statistics.median(times),
        "seconds_min": min(times),
        "bytes": statistics.median(sent),
        "requests": statistics.median(requests),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--segments", type=int, default=16)
    parser.add_argument("--video-mb", type=int, default=40)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    segment = f"{ROUTE}/{args.segments // 2}"
    results = {"segments": args.segments}
    with tempfile.TemporaryDirectory() as folder:
        results["archive_bytes"] = build(Path(folder), args.segments, args.video_mb)
        with Server(folder) as server:
            results["range_one_segment"] = timed(
                server,
                lambda home: fetch_comma2k19(
                    segments=segment, data_home=home, base_url=server.url, progress=False
                ),
                args.repeats,
            )
            results["archive_one_segment"] = timed(
                server,
                lambda home: fetch_comma2k19(
                    segments=segment,
                    data_home=home,
                    base_url=server.url,
                    method="archive",
                    checksums={},
                    progress=False,
                ),
                1,
            )
            scan = timed(
                server,
                lambda home: scan_comma2k19(chunks=1, base_url=server.url, progress=False),
                max(1, args.repeats // 2),
            )
            scan["seconds_per_segment"] = scan["seconds_median"] / args.segments
            scan["bytes_per_segment"] = scan["bytes"] / args.segments
            results["scan"] = scan
    print(json.dumps(results, indent=2))


if __name__ == "__main__":
    import warnings

    warnings.simplefilter("ignore", UserWarning)  # "no SHA-256 known" of the archive method
    main()
