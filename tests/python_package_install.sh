#!/usr/bin/env bash
# `pip install client/python` as a user does it on Debian 12: into a virtual
# environment that sees apt's numpy, with no package index (nothing may be
# downloaded), then the installed package (not the source tree) loads the C
# library and answers.
set -euo pipefail
source_dir=$1 library=$2 venv=$3
rm -rf "$venv"
/usr/bin/python3 -m venv --system-site-packages "$venv"
# From a copy: pip's legacy build writes build/ and *.egg-info next to setup.py.
cp -r "$source_dir" "$venv/source"
"$venv/bin/pip" install --no-index --no-cache-dir --quiet "$venv/source"
cd "$(dirname "$venv")"  # not the source tree: the import must find the installed copy
FILIGREE_LIBRARY=$library "$venv/bin/python" - <<'PY'
import filigree, pathlib, sys
where = pathlib.Path(filigree.__file__).resolve()
assert "site-packages" in where.parts, f"imported from {where}, not the installed package"
assert filigree.library_version().count(".") == 2
try:
    filigree.Client("127.0.0.1:1").join("s", "t")
except filigree.Unavailable as e:
    print(f"installed at {where.parent}; library {filigree.library_version()}; a server that is down: {e.status.name}")
else:
    sys.exit("a join with no server did not fail")
PY
rm -rf "$venv"
