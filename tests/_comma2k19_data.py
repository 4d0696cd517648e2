"""Where the tests find the comma2k19 example segment: ``shared/`` beside the checkout (as
``conftest.py`` finds it), so that the tests run from any clone and skip without it."""

from pathlib import Path

import pytest

SHARED = Path(__file__).resolve().parents[2] / "shared"
ROUTE = "b0c9d2329ad1606b|2018-08-02--08-34-47"
SEGMENT = SHARED / "data" / "comma2k19" / "b0c9d2329ad1606b--2018-08-02--08-34-47" / "40"
SEGMENT_NAME = f"{ROUTE}--40"
needs_segment = pytest.mark.skipif(not SEGMENT.is_dir(), reason="comma2k19 example not present")
