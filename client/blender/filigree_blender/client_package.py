"""Imports the `filigree` Python package: installed, or the copy bundled in
the add-on zip (vendor/), with libfiligree.so from the add-on's preferences
when set."""

from __future__ import annotations

import os
import sys
from pathlib import Path

_VENDOR = Path(__file__).resolve().parent / "vendor"


def load(library_path: str = ""):
    """The filigree module. Raises ImportError with what to do when the
    package or its C library cannot be found."""
    if library_path:
        os.environ["FILIGREE_LIBRARY"] = library_path  # read when the package loads the library
    try:
        import filigree
    except ModuleNotFoundError:
        if _VENDOR.is_dir() and str(_VENDOR) not in sys.path:
            sys.path.append(str(_VENDOR))
        import filigree
    return filigree
