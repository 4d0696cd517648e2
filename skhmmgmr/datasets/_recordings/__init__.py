"""A user's own recordings: read from CSV or Parquet files into the tidy frame, put on a
uniform time grid, and their target shifted ahead within every recording.

Private: the public names are re-exported by :mod:`skhmmgmr.datasets`; ``read_table`` (one
file read, every failure naming it) is the command line's too.
"""

from ._load import load_recordings, read_table
from ._resample import resample_recordings
from ._shift import shift_target

__all__ = ["load_recordings", "read_table", "resample_recordings", "shift_target"]
