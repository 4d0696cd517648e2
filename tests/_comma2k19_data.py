"""The comma2k19 segment of the tests: the sample that ships with the package, written out once
per test session as a segment folder (the layout of comma2k19), so that the folder loader, the
downloads and the damaged-file tests read the same real minute on any clone."""

import atexit
import shutil
import tempfile
from pathlib import Path

from skhmmgmr.datasets._comma2k19._sample import SAMPLE_NAME, SAMPLE_ROUTE, extract_sample

ROUTE = SAMPLE_ROUTE
SEGMENT_NAME = SAMPLE_NAME
_FOLDER = Path(tempfile.mkdtemp(prefix="skhmmgmr-comma2k19-"))
atexit.register(shutil.rmtree, _FOLDER, ignore_errors=True)
SEGMENT = extract_sample(_FOLDER)
