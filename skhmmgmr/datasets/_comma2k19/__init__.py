"""comma2k19, real driving data: a segment decoded from its CAN frames, the minute that ships
with the package, the segments fetched from the remote archive, and who steers in each.

Private: the public names are re-exported by :mod:`skhmmgmr.datasets`.
"""

from ._fetch import COMMA2K19_URL, fetch_comma2k19
from ._sample import load_comma2k19_sample
from ._scan import scan_comma2k19
from ._segment import load_comma2k19_segment

__all__ = [
    "COMMA2K19_URL",
    "fetch_comma2k19",
    "load_comma2k19_sample",
    "load_comma2k19_segment",
    "scan_comma2k19",
]
