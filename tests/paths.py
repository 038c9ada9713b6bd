"""Where the repository's parts are, for a test in any room's folder (tests/<room>/)."""

from pathlib import Path

#: the repository's root (the folder of README.md, src/, docs/, schemas/)
ROOT = Path(__file__).resolve().parent.parent
#: the package's source folder (PYTHONPATH of a test's subprocess)
SRC = ROOT / "src"
