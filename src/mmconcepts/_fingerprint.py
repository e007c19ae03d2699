"""A fingerprint of the code that produces a result or a cache (internal).

Results and caches are keyed on :func:`code_fingerprint`, not on the package version
(which does not change when the code does): editing any source file of the package, or
installing another version of a dependency that computes numbers, gives a new fingerprint,
so a result or a cached feature computed by other code is recomputed rather than reused.
"""

from __future__ import annotations

import functools
import hashlib
from importlib import metadata
from pathlib import Path
from typing import TypedDict

__all__ = ["code_fingerprint", "fingerprint_parts", "DEPENDENCIES"]

#: Distributions whose version can change the numbers (absent ones are recorded as absent).
DEPENDENCIES = (
    "numpy",
    "scipy",
    "scikit-learn",
    "numba",
    "joblib",
    "librosa",
    "soundfile",
    "soxr",
    "scikit-image",
    "piper-tts",
    "onnxruntime",
    "espeakng-loader",
)

_PACKAGE_ROOT = Path(__file__).resolve().parent
_SUFFIXES = (".py", ".css")


def _source_files(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.suffix in _SUFFIXES and p.is_file() and "__pycache__" not in p.parts)


def _dependency_versions() -> dict[str, str | None]:
    out: dict[str, str | None] = {}
    for name in DEPENDENCIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


class FingerprintParts(TypedDict):
    """What :func:`fingerprint_parts` returns."""

    source: str
    dependencies: dict[str, str | None]


def fingerprint_parts(root: Path | None = None) -> FingerprintParts:
    """What the fingerprint is made of: the source digest and the dependency versions.

    Parameters
    ----------
    root : Path, optional
        The package folder to hash (default: the installed ``mmconcepts`` package).

    Returns
    -------
    dict
        ``{"source": sha256 hex of every .py/.css file's relative path and bytes,
        "dependencies": {distribution: version or None}}``.
    """
    root = _PACKAGE_ROOT if root is None else Path(root)
    h = hashlib.sha256()
    for path in _source_files(root):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    return {"source": h.hexdigest(), "dependencies": _dependency_versions()}


@functools.lru_cache(maxsize=None)
def _cached(root: str) -> str:
    parts = fingerprint_parts(Path(root))
    h = hashlib.sha256(parts["source"].encode())
    for name, version in sorted(parts["dependencies"].items()):
        h.update(f"\n{name}=={version}".encode())
    return h.hexdigest()[:16]


def code_fingerprint(root: Path | None = None) -> str:
    """A 16-hex-digit digest of the package's source files and its dependencies' versions.

    Computed once per process (the source files are read at the first call). Use it in
    every cache key and result key instead of ``mmconcepts.__version__``.

    Parameters
    ----------
    root : Path, optional
        The package folder to hash (default: the installed ``mmconcepts`` package).
    """
    return _cached(str((_PACKAGE_ROOT if root is None else Path(root)).resolve()))
