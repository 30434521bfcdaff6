#!/usr/bin/env python3
"""Makes the add-on zip Blender installs: filigree_blender/ with the
`filigree` Python package bundled in filigree_blender/vendor/.
Usage: make_addon_zip.py OUT.zip"""

import sys
import zipfile
from pathlib import Path

client = Path(__file__).resolve().parent.parent
with zipfile.ZipFile(sys.argv[1], "w", zipfile.ZIP_DEFLATED) as z:
    for f in sorted((client / "blender/filigree_blender").rglob("*.py")):
        z.write(f, f.relative_to(client / "blender"))
    for f in sorted((client / "python/filigree").rglob("*")):
        if f.suffix in (".py", ".typed"):
            z.write(f, Path("filigree_blender/vendor") / f.relative_to(client / "python"))
