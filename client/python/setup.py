# The `filigree` Python package: pure Python over libfiligree.so (ctypes), so
# nothing is compiled or downloaded here. setup.py without pyproject.toml on
# purpose: pip then builds with the setuptools apt installed instead of
# fetching one into an isolated environment (there is no PyPI here).
from setuptools import setup

setup(
    name="filigree",
    version="0.1.0",
    description="Python client of the Filigree deformation service (numpy in and out)",
    packages=["filigree"],
    package_data={"filigree": ["py.typed"]},
    python_requires=">=3.9",
    install_requires=["numpy"],
)
