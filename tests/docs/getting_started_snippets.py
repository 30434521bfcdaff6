#!/usr/bin/python3
"""Runs the code blocks of docs/getting-started.md against a fresh server.

The page marks its blocks with an HTML comment on the line before the fence:

  <!-- run -->          a ```sh block: run, in order, in one bash (set -euo pipefail),
                        so variables a block exports are there for the next ones
  <!-- file: NAME -->   a block (```python, ...) written to NAME in the working
                        directory when its turn comes; a later `run` block runs it
  <!-- env -->          a ```sh block of `export NAME=...` lines that say where the
                        tools and the server are: not run; this test provides every
                        variable it names (a fresh server on ephemeral ports, the
                        binaries under test), and fails if the page names one it
                        does not know

Unmarked blocks (make demo, starting the server by hand) are not run. The
blocks run in a scratch directory holding `data` (a link to the clone's) and
`out`; `python3` is /usr/bin/python3 (Debian's, with numpy). The first block
that fails ends the test with its text and output.

Usage: getting_started_snippets.py --server BIN --cli BIN --library LIB
       --source SRC_DIR --work SCRATCH_DIR [--page PAGE]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import urllib.request
from dataclasses import dataclass
from pathlib import Path

MARK = re.compile(r"^<!--\s*(run|env|file:\s*(\S+))\s*-->\s*$")
FENCE = re.compile(r"^```(\w*)\s*$")
EXPORT = re.compile(r"^\s*export\s+([A-Za-z_][A-Za-z0-9_]*)=")


@dataclass
class Block:
    kind: str  # run, env, file
    language: str
    text: str
    line: int  # of the opening fence, 1-based
    name: str = ""  # file blocks: where to write it


def blocks_of(page: Path) -> list[Block]:
    lines = page.read_text().splitlines()
    found: list[Block] = []
    i = 0
    while i < len(lines):
        mark = MARK.match(lines[i])
        i += 1
        if not mark:
            continue
        while i < len(lines) and not lines[i].strip():
            i += 1
        fence = FENCE.match(lines[i]) if i < len(lines) else None
        if not fence:
            sys.exit(f"FAIL: {page}:{i}: the marker '{mark.group(0)}' is not followed by a code block")
        start = i + 1
        i += 1
        body = []
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        if i == len(lines):
            sys.exit(f"FAIL: {page}:{start}: the code block never closes")
        i += 1
        kind = "file" if mark.group(2) else mark.group(1)
        if kind in ("run", "env") and fence.group(1) not in ("sh", "bash"):
            sys.exit(f"FAIL: {page}:{start}: a '{kind}' block must be ```sh, not ```{fence.group(1)}")
        found.append(Block(kind, fence.group(1), "\n".join(body) + "\n", start, mark.group(2) or ""))
    return found


def start_server(binary: str, data_dir: Path, web_root: Path | None) -> tuple[subprocess.Popen, str, str]:
    command = [binary, "--listen", "127.0.0.1:0", "--http", "127.0.0.1:0", "--data-dir", str(data_dir),
               "--log-level", "warn"]
    if web_root is not None:
        command += ["--web-root", str(web_root)]
    server = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    grpc = http = ""
    while not (grpc and http):  # it prints both once it accepts calls
        line = server.stdout.readline()
        if not line:
            server.wait(timeout=30)
            sys.exit(f"FAIL: filigree-server did not start (exit {server.returncode}): {server.stderr.read()}")
        if line.startswith("listening on "):
            grpc = line.split()[-1]
        elif line.startswith("http on "):
            http = line.split()[-1]
    return server, grpc, http


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--server", required=True, help="the filigree-server binary")
    parser.add_argument("--cli", required=True, help="the filigree binary")
    parser.add_argument("--library", required=True, help="libfiligree.so")
    parser.add_argument("--source", required=True, type=Path, help="the clone's root")
    parser.add_argument("--work", required=True, type=Path, help="a scratch directory (emptied)")
    parser.add_argument("--page", type=Path, help="default: SOURCE/docs/getting-started.md")
    args = parser.parse_args()
    source = args.source.resolve()
    page = args.page or source / "docs" / "getting-started.md"
    blocks = blocks_of(page)
    if not any(b.kind == "run" for b in blocks) or not any(b.kind == "file" and b.language == "python" for b in blocks):
        print(f"FAIL: {page} marks no runnable sh block or no python file block", file=sys.stderr)
        return 1

    work = args.work.resolve()
    shutil.rmtree(work, ignore_errors=True)
    (work / "bin").mkdir(parents=True)
    (work / "run").mkdir()
    (work / "run" / "data").symlink_to(source / "data")
    for name, target in (("filigree", args.cli), ("filigree-server", args.server), ("python3", "/usr/bin/python3")):
        (work / "bin" / name).symlink_to(Path(target).resolve())

    web_root = source / "web_viewer" / "dist"
    server, grpc, http = start_server(args.server, work / "server-data",
                                      web_root if (web_root / "index.html").exists() else None)
    try:
        provided = {
            "PATH": f"{work / 'bin'}:{os.environ.get('PATH', '/usr/bin:/bin')}",
            "PYTHONPATH": str(source / "client" / "python"),
            "FILIGREE_LIBRARY": str(Path(args.library).resolve()),
            "FILIGREE_SERVER": grpc,
            "FILIGREE_HTTP": http,
        }
        for b in blocks:
            if b.kind != "env":
                continue
            for line in b.text.splitlines():
                m = EXPORT.match(line)
                if m and m.group(1) not in provided:
                    print(f"FAIL: {page}:{b.line}: the page sets {m.group(1)}, which this test does not provide; "
                          f"teach tests/docs/getting_started_snippets.py what it should be", file=sys.stderr)
                    return 1
        env = dict(os.environ, **provided, PYTHONDONTWRITEBYTECODE="1")
        env.pop("FILIGREE_TOKEN", None)

        # One bash for every block, so exported variables carry over; each
        # block first records its number, so a failure names its block.
        progress = work / "block"
        script = ["set -euo pipefail"]
        steps = [b for b in blocks if b.kind in ("run", "file")]
        for n, b in enumerate(steps):
            script.append(f"echo {n} > '{progress}'")
            script.append(f"echo '== {page.name}:{b.line} ({b.kind}{': ' + b.name if b.name else ''})'")
            if b.kind == "file":
                script.append(f"cat > '{b.name}' <<'FILIGREE_SNIPPET_END'\n{b.text}FILIGREE_SNIPPET_END")
            else:
                script.append(b.text)
        script.append(f"echo done > '{progress}'")
        (work / "snippets.sh").write_text("\n".join(script) + "\n")
        result = subprocess.run(["bash", str(work / "snippets.sh")], cwd=work / "run", env=env,
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, timeout=600)
        print(result.stdout, end="")
        reached = progress.read_text().strip() if progress.exists() else "0"
        if result.returncode != 0 or reached != "done":
            b = steps[int(reached)] if reached.isdigit() else steps[0]
            print(f"\nFAIL: the block at {page}:{b.line} failed (exit {result.returncode}):\n"
                  f"```{b.language}\n{b.text}```", file=sys.stderr)
            return 1
        if server.poll() is not None:
            print(f"FAIL: filigree-server exited ({server.returncode}) while the blocks ran: {server.stderr.read()}",
                  file=sys.stderr)
            return 1

        # The viewer address the page prints is served (when the viewer is built).
        if web_root.exists():
            with urllib.request.urlopen(f"http://{http}/", timeout=30) as answer:
                if answer.status != 200 or b"<html" not in answer.read(4096).lower():
                    print(f"FAIL: http://{http}/ did not serve the viewer's page", file=sys.stderr)
                    return 1
        print(f"PASS: {len(steps)} blocks of {page.name} ran against a fresh filigree-server")
        return 0
    finally:
        server.terminate()
        try:
            server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
        shutil.rmtree(work / "server-data", ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
