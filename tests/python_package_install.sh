#!/usr/bin/env bash
# `pip install client/python` as a user does it on Debian 12: into a virtual
# environment that sees apt's numpy, with no package index (nothing may be
# downloaded), then the installed package (not the source tree) loads the C
# library and answers.
set -euo pipefail
source_dir=$1 library=$2 venv=$3
rm -rf "$venv"

# Another interpreter than Debian's (pyenv's, on these machines), with no
# setuptools of its own to lend pip: the package's own build backend needs
# nothing, so pip builds and installs it offline all the same. (numpy is
# not there to import: --no-deps, and the installed files are checked.)
other=$(command -v python3.11 || true)
for candidate in /root/.pyenv/versions/*/bin/python3 $other; do
  [ -x "$candidate" ] && [ "$(readlink -f "$candidate")" != "$(readlink -f /usr/bin/python3)" ] && { other=$candidate; break; }
done
[ -n "$other" ] && [ "$(readlink -f "$other")" != "$(readlink -f /usr/bin/python3)" ] ||
  { echo "python_package_install: no Python other than /usr/bin/python3 here to install with" >&2; exit 1; }
"$other" -m venv "$venv"
cp -r "$source_dir" "$venv/source"
"$venv/bin/python" -m pip install --no-index --no-cache-dir --no-deps --quiet "$venv/source"
# Captured first: `| grep -q` would end pip's write early (SIGPIPE), a failure under pipefail.
installed=$("$venv/bin/python" -m pip show --files filigree)
grep -q "filigree/client.py" <<<"$installed" ||
  { echo "python_package_install: $other installed no filigree/client.py: $installed" >&2; exit 1; }
echo "installed offline with $("$other" --version) too (its own venv, no setuptools)"
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
