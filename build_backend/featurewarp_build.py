"""featurewarp's PEP 517 build backend: setuptools', after a check of what the build needs.

Installing featurewarp compiles C twice: its own rasterizer (``featurewarp_cli/render/_raster.c``)
and scikit-sparse, which has no wheels and builds against SuiteSparse's CHOLMOD headers.
Without a C compiler or without ``cholmod.h`` pip would end, minutes in, in a compiler's error
(``cholmod.h: No such file or directory``). pip asks this backend for featurewarp's build
requirements and metadata before it builds any dependency, so the check here runs first and
ends the install with one message naming the packages to install (Debian/Ubuntu, Fedora,
macOS Homebrew).

What is checked (:func:`missing`):

- a C compiler: ``$CC`` or the one Python was built with, run on an empty file (``-E``);
- the Python headers (``Python.h``), which any C extension needs;
- ``cholmod.h``, unless scikit-sparse is already installed in the target Python: in
  ``$SUITESPARSE_INCLUDE_DIR`` (scikit-sparse's own variable), the folders scikit-sparse's
  build adds (``sys.prefix/include``, ``/usr/include/suitesparse``, Homebrew's), the usual
  system folders, ``$CPATH`` / ``$C_INCLUDE_PATH`` and ``-I`` in ``$CFLAGS`` / ``$CPPFLAGS``;
  when none holds it, the compiler is asked too (its own search path).

Environment variables:

``FEATUREWARP_HEADER_DIRS``
    Folders (``os.pathsep``-separated) to look for ``cholmod.h`` in *instead of* the usual
    ones, and the compiler is not asked: to see the message where the headers are installed,
    ``FEATUREWARP_HEADER_DIRS=/nonexistent pip install .``. Empty (``export VAR=``, as CI
    templates write it) or naming no folder, it counts as unset.
``FEATUREWARP_NO_BUILD_CHECK=1``
    Skip the check (for a build this check misjudges; the compiler then has the last word).
    ``1``, ``true`` or ``yes`` (any case) skip it; any other value (``0``, ``false``, empty)
    does not.
"""

from __future__ import annotations

import glob
import os
import shlex
import shutil
import subprocess
import sys
import sysconfig
import tempfile

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F401,F403  (every hook this module does not wrap)

#: Where each distribution keeps what is missing: (what, Debian/Ubuntu, Fedora, macOS Homebrew).
PACKAGES = {
    "compiler": ("a C compiler", "build-essential", "gcc", "xcode-select --install"),
    "python": ("the Python headers (Python.h)", "python3-dev", "python3-devel", None),
    "cholmod": ("SuiteSparse's CHOLMOD headers (cholmod.h, for scikit-sparse)", "libsuitesparse-dev",
                "suitesparse-devel", "brew install suite-sparse"),
}
#: System folders that may hold cholmod.h (scikit-sparse's build adds the suitesparse ones).
SYSTEM_DIRS = ("/usr/include/suitesparse", "/usr/include", "/usr/local/include/suitesparse", "/usr/local/include",
               "/opt/homebrew/include/suitesparse", "/opt/homebrew/include", "/opt/homebrew/opt/suite-sparse/include",
               "/opt/homebrew/opt/suite-sparse/include/suitesparse", "/usr/local/opt/suite-sparse/include",
               "/usr/local/opt/suite-sparse/include/suitesparse")


def compiler_command(environ=os.environ) -> list[str]:
    """The C compiler setuptools will call: ``$CC``, else the one Python was built with."""
    return shlex.split(environ.get("CC") or sysconfig.get_config_var("CC") or "cc")


def compiler_works(command: list[str], source: str = "", flags: list[str] = ()) -> bool:
    """Whether ``command`` preprocesses the C ``source`` (``-E``) with ``flags``, quietly."""
    with tempfile.TemporaryDirectory() as folder:
        path = os.path.join(folder, "probe.c")
        with open(path, "w") as file:
            file.write(source + "\n")
        try:
            run = subprocess.run([*command, *flags, "-E", path], capture_output=True, timeout=60)
        except (OSError, subprocess.SubprocessError):
            return False
    return run.returncode == 0


#: Values of ``FEATUREWARP_NO_BUILD_CHECK`` that skip the check (any case); others do not.
SKIP_VALUES = ("1", "true", "yes")


def given_header_dirs(environ=os.environ) -> list[str] | None:
    """The folders ``FEATUREWARP_HEADER_DIRS`` names; None where it is unset, empty or names none."""
    given = [d for d in environ.get("FEATUREWARP_HEADER_DIRS", "").split(os.pathsep) if d.strip()]
    return given or None


def header_dirs(environ=os.environ) -> list[str]:
    """Folders that may hold ``cholmod.h``, in the order scikit-sparse's build and the compiler
    would look (``FEATUREWARP_HEADER_DIRS`` replaces them all)."""
    if given_header_dirs(environ) is not None:
        return given_header_dirs(environ)
    flags = shlex.split(environ.get("CPPFLAGS", "")) + shlex.split(environ.get("CFLAGS", ""))
    from_flags = [flag[2:] for flag in flags if flag.startswith("-I") and len(flag) > 2]
    paths = [d for name in ("CPATH", "C_INCLUDE_PATH") for d in environ.get(name, "").split(os.pathsep) if d]
    own = [environ["SUITESPARSE_INCLUDE_DIR"]] if environ.get("SUITESPARSE_INCLUDE_DIR") else []
    prefixes = [os.path.join(sys.prefix, "include"), os.path.join(sys.prefix, "include", "suitesparse")]
    return own + from_flags + paths + prefixes + list(SYSTEM_DIRS) + glob.glob("/usr/local/Cellar/suite-sparse/*/include*")


def has_cholmod_header(environ=os.environ, compiler: list[str] | None = None) -> bool:
    """Whether ``cholmod.h`` is in one of :func:`header_dirs`, or (unless those were given by
    ``FEATUREWARP_HEADER_DIRS``) the ``compiler`` finds it with them."""
    folders = header_dirs(environ)
    if any(os.path.isfile(os.path.join(folder, "cholmod.h")) for folder in folders):
        return True
    if compiler is None or given_header_dirs(environ) is not None:
        return False
    return compiler_works(compiler, "#include <cholmod.h>", [f"-I{folder}" for folder in folders if os.path.isdir(folder)])


def scikit_sparse_installed() -> bool:
    """Whether the Python being installed into already has scikit-sparse (pip then builds
    nothing against CHOLMOD). Asked in a fresh ``-I`` process: pip's isolated build hides the
    target's packages from this one."""
    probe = "import importlib.util, sys; sys.exit(importlib.util.find_spec('sksparse') is None)"
    try:
        return subprocess.run([sys.executable, "-I", "-c", probe], capture_output=True, timeout=60).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


def missing(environ=os.environ) -> list[str]:
    """What the build needs and this machine lacks: keys of :data:`PACKAGES`, in that order."""
    compiler = compiler_command(environ)
    found = {"compiler": compiler_works(compiler),
             "python": os.path.isfile(os.path.join(sysconfig.get_paths()["include"], "Python.h"))}
    found["cholmod"] = scikit_sparse_installed() or has_cholmod_header(environ, compiler if found["compiler"] else None)
    return [key for key, there in found.items() if not there]


def message(keys: list[str], environ=os.environ) -> str:
    """The lines that tell what to install for ``keys`` (of :data:`PACKAGES`) and where."""
    needs = [PACKAGES[key] for key in keys]
    lines = [f"featurewarp cannot be built here, missing: {', '.join(need[0] for need in needs)}. "
             "Install, then install featurewarp again:",
             "  Debian/Ubuntu:   sudo apt-get install " + " ".join(need[1] for need in needs),
             "  Fedora:          sudo dnf install " + " ".join(need[2] for need in needs)]
    mac = [need[3] for need in needs if need[3]]
    if mac:
        lines.append("  macOS:           " + " && ".join(mac))
    if "compiler" in keys:
        lines.append(f"  (the compiler looked for: {shlex.join(compiler_command(environ))}; set CC to use another)")
    if "cholmod" in keys:
        lines.append("  (cholmod.h elsewhere: SUITESPARSE_INCLUDE_DIR=/its/folder pip install (or pipx install) ...)")
    return "\n".join(lines)


def check(environ=os.environ) -> None:
    """End the build (exit status 1, :func:`message` on stderr, no traceback) when something
    it needs is missing; nothing when ``FEATUREWARP_NO_BUILD_CHECK`` is one of :data:`SKIP_VALUES`
    (``0`` and ``false`` skipped it too)."""
    if environ.get("FEATUREWARP_NO_BUILD_CHECK", "").strip().lower() in SKIP_VALUES:
        return
    keys = missing(environ)
    if keys:
        raise SystemExit(message(keys, environ))


def get_requires_for_build_wheel(config_settings=None):
    check()
    return _setuptools.get_requires_for_build_wheel(config_settings)


def get_requires_for_build_editable(config_settings=None):
    check()
    return _setuptools.get_requires_for_build_editable(config_settings)


def prepare_metadata_for_build_wheel(metadata_directory, config_settings=None):
    check()
    return _setuptools.prepare_metadata_for_build_wheel(metadata_directory, config_settings)


def prepare_metadata_for_build_editable(metadata_directory, config_settings=None):
    check()
    return _setuptools.prepare_metadata_for_build_editable(metadata_directory, config_settings)
