"""fsspec URLs (``s3://bucket/a.jpg``, ``gs://``, ``memory://``, ``file://`` ...) for the batch's
inputs, masks and outputs, where fsspec and the URL's back-end are installed.

Plain paths never come here (:func:`is_url` is a regular expression, fsspec is imported only
for a URL). A ``file://`` URL becomes its local path (:func:`local_path`), so it gets every
guarantee of a plain path. Any other URL is read whole into memory, and written all or
nothing (:func:`put`): in one put of the complete bytes where the store makes an object
appear only when it is complete (object stores, ``memory://``), else to a hidden temporary
key beside the target that is then moved onto it.

Every failure to reach a URL is a ``ValueError`` or an ``OSError`` whose text is one line
naming the URL or what to install (``s3:// needs s3fs: pip install s3fs``).
"""

from __future__ import annotations

import posixpath
import re
import uuid

#: ``protocol://`` or a chain ``protocol::`` at the start: a URL, not a path.
URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*(?:://|::)")
#: Glob characters: a URL holding one names every object it matches (``s3://b/photos/*.jpg``).
GLOB = re.compile(r"[*?\[]")
#: Protocols whose single put makes the object appear only complete (no temporary key needed).
WHOLE_PUT = {"s3", "s3a", "gs", "gcs", "az", "abfs", "abfss", "adl", "oci", "oss", "memory"}
#: Prefix of the hidden key an output waits under where a put is not atomic.
TEMP_PREFIX = ".featurewarp-"


def is_url(path: str | None) -> bool:
    """Whether ``path`` is an fsspec URL (``protocol://...`` or a ``a::b://`` chain)."""
    return bool(path) and URL.match(path) is not None


def protocol(url: str) -> str:
    """The URL's (outermost) protocol: ``s3`` of ``s3://b/k``."""
    return re.split(r"://|::", url, maxsplit=1)[0].lower()


def _fsspec():
    try:
        import fsspec
    except ImportError:
        raise ValueError("URLs need fsspec: pip install fsspec (or 'featurewarp[dask]')") from None
    return fsspec


def filesystem(url: str):
    """``(file system, path in it)`` for ``url``.

    Raises
    ------
    ValueError
        fsspec missing, an unknown protocol, or a back-end not installed, naming the package
        to install.
    """
    fsspec = _fsspec()
    name = protocol(url)
    try:
        fsspec.get_filesystem_class(name)
    except ValueError:
        raise ValueError(f"{url}: unknown protocol {name}:// (not one fsspec knows)") from None
    except ImportError as err:
        raise ValueError(f"{name}:// needs {_backend(name, err)}") from None
    try:
        return fsspec.core.url_to_fs(url)
    except ImportError as err:                     # a chain's inner protocol
        raise ValueError(f"{url}: needs {_backend(protocol(url.split('::', 1)[-1]), err)}") from None


def _backend(name: str, err: ImportError) -> str:
    """``s3fs: pip install s3fs``: what to install for protocol ``name``."""
    from fsspec.registry import known_implementations

    spec = known_implementations.get(name, {})
    module = spec.get("class", "").split(".")[0]
    if module and module != "fsspec":
        return f"{module}: pip install {module}"
    packages = re.findall(r'"([A-Za-z0-9_.\-]+)"', spec.get("err", "")) or [getattr(err, "name", None) or "?"]
    return f"{' and '.join(packages)}: pip install {' '.join(packages)}"


def local_path(url: str) -> str | None:
    """The local path of a ``file://`` (or ``local://``) URL; None for any other."""
    if protocol(url) not in ("file", "local") or "::" in url:
        return None
    return filesystem(url)[1]


def expand(url: str) -> list[str]:
    """``url`` itself, or with glob characters every object it matches, sorted
    (ValueError when none does)."""
    if not GLOB.search(url.split("://", 1)[-1]):
        return [url]
    fs, path = filesystem(url)
    found = [_url_of(fs, url, p) for p in sorted(fs.glob(path)) if fs.isfile(p)]
    if not found:
        raise ValueError(f"{url} matches nothing")
    return found


def _url_of(fs, like: str, path: str) -> str:
    """The URL of ``path`` in ``fs``, in the form of ``like`` (its protocol and chain)."""
    head = like[: like.index("://") + 3] if "://" in like else ""
    return head + (path[1:] if head.startswith("memory") and path.startswith("/") else path)


def key(url: str) -> str:
    """What ``url`` names, for comparing two URLs (protocol and normalised path)."""
    fs, path = filesystem(url)
    name = fs.protocol if isinstance(fs.protocol, str) else fs.protocol[0]
    return f"{name}://{path}"


def join(folder: str, name: str) -> str:
    """``name`` in the URL ``folder`` (``name`` itself when it is a URL or absolute)."""
    if is_url(name) or name.startswith("/"):
        return name
    return folder.rstrip("/") + "/" + name


def dirname(url: str) -> str:
    return posixpath.dirname(url)


def basename(url: str) -> str:
    return posixpath.basename(url)


def isfile(url: str) -> bool:
    fs, path = filesystem(url)
    try:
        return fs.isfile(path)
    except OSError:
        return False


def read(url: str) -> bytes:
    """The whole object (FileNotFoundError when there is none)."""
    fs, path = filesystem(url)
    return fs.cat_file(path)


def size(url: str) -> int:
    fs, path = filesystem(url)
    return int(fs.size(path))


def modified(url: str) -> float | None:
    """POSIX time the object was last written, or None where the store does not say (or
    there is none)."""
    fs, path = filesystem(url)
    try:
        stamp = fs.modified(path)
    except (NotImplementedError, OSError, KeyError, ValueError, AttributeError):
        return None
    if stamp.tzinfo is None:                     # fsspec's stores give UTC
        from datetime import timezone

        stamp = stamp.replace(tzinfo=timezone.utc)
    return stamp.timestamp()


def makedirs(url: str) -> None:
    """Create the folder ``url`` where the store has folders (object stores have none)."""
    fs, path = filesystem(url)
    fs.makedirs(path, exist_ok=True)


def put(url: str, data: bytes) -> None:
    """Write ``data`` to ``url`` all or nothing (see the module's docstring); OSError on failure."""
    fs, path = filesystem(url)
    names = fs.protocol if isinstance(fs.protocol, tuple) else (fs.protocol,)
    if WHOLE_PUT.intersection(names):
        fs.pipe_file(path, data)
        return
    temp = posixpath.join(posixpath.dirname(path), f"{TEMP_PREFIX}{uuid.uuid4().hex}.tmp")
    fs.pipe_file(temp, data)
    try:
        fs.mv(temp, path)
    except BaseException:
        try:
            fs.rm(temp)
        except OSError:
            pass
        raise
