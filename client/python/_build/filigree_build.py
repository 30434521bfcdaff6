"""The `filigree` package's own PEP 517 build backend: the package is pure
Python (ctypes over libfiligree.so), so a wheel is its files in a zip with
their metadata. Needing nothing to build, `pip install client/python` works
offline with any Python >= 3.9, not only one whose setuptools pip can find
(pip would otherwise fetch setuptools into its isolated build environment)."""

from __future__ import annotations

import base64
import hashlib
import pathlib
import zipfile

NAME, VERSION = "filigree", "0.1.0"
ROOT = pathlib.Path(__file__).resolve().parent.parent
METADATA = f"""Metadata-Version: 2.1
Name: {NAME}
Version: {VERSION}
Summary: Python client of the Filigree deformation service (numpy in and out)
Requires-Python: >=3.9
Requires-Dist: numpy
"""
WHEEL = """Wheel-Version: 1.0
Generator: filigree_build
Root-Is-Purelib: true
Tag: py3-none-any
"""


def _files() -> list[pathlib.Path]:
    package = ROOT / NAME
    return sorted(p for p in package.rglob("*") if p.is_file() and p.suffix in (".py", ".typed") and
                  "__pycache__" not in p.parts)


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def get_requires_for_build_wheel(config_settings=None):
    return []


def get_requires_for_build_sdist(config_settings=None):
    return []


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    wheel = f"{NAME}-{VERSION}-py3-none-any.whl"
    info = f"{NAME}-{VERSION}.dist-info"
    entries = [(p.relative_to(ROOT).as_posix(), p.read_bytes()) for p in _files()]
    entries += [(f"{info}/METADATA", METADATA.encode()), (f"{info}/WHEEL", WHEEL.encode())]
    record = [_record_line(name, data) for name, data in entries] + [f"{info}/RECORD,,"]
    with zipfile.ZipFile(pathlib.Path(wheel_directory) / wheel, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in entries:
            z.writestr(name, data)
        z.writestr(f"{info}/RECORD", "\n".join(record) + "\n")
    return wheel


def build_sdist(sdist_directory, config_settings=None):
    import tarfile

    sdist = f"{NAME}-{VERSION}.tar.gz"
    base = f"{NAME}-{VERSION}"
    with tarfile.open(pathlib.Path(sdist_directory) / sdist, "w:gz") as t:
        for p in _files() + [ROOT / "pyproject.toml", ROOT / "_build" / "filigree_build.py"]:
            t.add(p, arcname=f"{base}/{p.relative_to(ROOT).as_posix()}")
        info = tarfile.TarInfo(f"{base}/PKG-INFO")
        data = METADATA.encode()
        info.size = len(data)
        import io

        t.addfile(info, io.BytesIO(data))
    return sdist
