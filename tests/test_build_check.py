"""The build backend's check (issue 25 item 5): a missing C compiler, Python.h or cholmod.h
ends ``pip install`` in one message naming the packages to install, before any dependency
is built. The check function is tested here; a real ``pip install`` with the headers hidden
(``FEATUREWARP_HEADER_DIRS=/nonexistent``) is in the module's docstring and the README."""

from __future__ import annotations

import importlib.util
import os
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SPEC = importlib.util.spec_from_file_location("featurewarp_build", ROOT / "build_backend" / "featurewarp_build.py")
build = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(build)

EVERY_PACKAGE = ("build-essential", "libsuitesparse-dev", "gcc", "suitesparse-devel", "suite-sparse",
                 "xcode-select --install")


def test_pyproject_builds_through_the_checking_backend():
    system = tomllib.loads((ROOT / "pyproject.toml").read_text())["build-system"]
    assert system["build-backend"] == "featurewarp_build" and system["backend-path"] == ["build_backend"]
    for hook in ("get_requires_for_build_wheel", "prepare_metadata_for_build_wheel", "build_wheel", "build_sdist",
                 "get_requires_for_build_editable", "prepare_metadata_for_build_editable", "build_editable"):
        assert callable(getattr(build, hook)), hook


def test_nothing_is_missing_here():
    """This machine built the package: the check passes (make install put everything there)."""
    assert build.missing(dict(os.environ)) == []
    assert build.compiler_works(build.compiler_command(os.environ))
    assert build.scikit_sparse_installed()


def test_the_header_is_looked_for_where_scikit_sparse_and_the_compiler_look(tmp_path):
    env = {"SUITESPARSE_INCLUDE_DIR": "/own", "CFLAGS": "-O2 -I/from/cflags", "CPPFLAGS": "-I /spaced",
           "CPATH": f"/cpath{os.pathsep}/cpath2"}
    folders = build.header_dirs(env)
    assert folders[:4] == ["/own", "/from/cflags", "/cpath", "/cpath2"]
    assert "/usr/include/suitesparse" in folders and "/opt/homebrew/include/suitesparse" in folders
    assert build.header_dirs({"FEATUREWARP_HEADER_DIRS": f"{tmp_path}{os.pathsep}/x"}) == [str(tmp_path), "/x"]
    hidden = {"FEATUREWARP_HEADER_DIRS": str(tmp_path)}
    assert not build.has_cholmod_header(hidden, build.compiler_command(os.environ))   # the compiler is not asked
    (tmp_path / "cholmod.h").write_text("/* a header */\n")
    assert build.has_cholmod_header(hidden)


def test_a_missing_compiler_and_header_are_one_message_naming_the_packages(tmp_path, monkeypatch):
    monkeypatch.setattr(build, "scikit_sparse_installed", lambda: False)
    env = {"CC": "/nonexistent/cc", "FEATUREWARP_HEADER_DIRS": str(tmp_path)}
    assert build.missing(env) == ["compiler", "cholmod"]
    with pytest.raises(SystemExit) as stop:
        build.check(env)
    text = str(stop.value.code)
    assert text.startswith("featurewarp cannot be built here, missing: a C compiler, SuiteSparse's CHOLMOD headers")
    assert all(package in text for package in EVERY_PACKAGE)
    assert "Debian/Ubuntu:   sudo apt-get install build-essential libsuitesparse-dev" in text
    assert "/nonexistent/cc" in text and "SUITESPARSE_INCLUDE_DIR" in text
    assert build.check({**env, "FEATUREWARP_NO_BUILD_CHECK": "1"}) is None


@pytest.mark.parametrize("keys, named, not_named", [
    (["cholmod"], ["libsuitesparse-dev", "suitesparse-devel", "brew install suite-sparse"], ["gcc", "CC"]),
    (["compiler"], ["build-essential", "dnf install gcc", "xcode-select"], ["suitesparse", "SUITESPARSE"]),
    (["python"], ["python3-dev", "python3-devel"], ["macOS", "gcc"]),
])
def test_the_message_names_only_what_is_missing(keys, named, not_named):
    text = build.message(keys, {"CC": "cc"})
    assert all(word in text for word in named) and not any(word in text for word in not_named)


def test_scikit_sparse_already_installed_needs_no_header(tmp_path, monkeypatch):
    monkeypatch.setattr(build, "scikit_sparse_installed", lambda: True)
    assert build.missing({"FEATUREWARP_HEADER_DIRS": str(tmp_path)}) == []


def test_an_empty_header_dirs_counts_as_unset(monkeypatch):
    """Hostile review D14: FEATUREWARP_HEADER_DIRS= (as CI templates export it) looked for
    cholmod.h in no folder, and stopped a machine that has it."""
    monkeypatch.setattr(build, "scikit_sparse_installed", lambda: False)
    for empty in ("", " ", os.pathsep):
        env = {**os.environ, "FEATUREWARP_HEADER_DIRS": empty}
        assert build.header_dirs(env) == build.header_dirs({k: v for k, v in env.items()
                                                            if k != "FEATUREWARP_HEADER_DIRS"})
        assert build.missing(env) == []


@pytest.mark.parametrize("value, skips", [("1", True), ("true", True), ("YES", True), (" True ", True),
                                          ("0", False), ("false", False), ("no", False), ("", False)])
def test_only_1_true_or_yes_skip_the_check(tmp_path, monkeypatch, value, skips):
    """D14: FEATUREWARP_NO_BUILD_CHECK=0 or false skipped the check as =1 does."""
    monkeypatch.setattr(build, "scikit_sparse_installed", lambda: False)
    env = {"FEATUREWARP_HEADER_DIRS": str(tmp_path), "FEATUREWARP_NO_BUILD_CHECK": value}
    if skips:
        assert build.check(env) is None
    else:
        with pytest.raises(SystemExit, match="missing: SuiteSparse's CHOLMOD headers"):
            build.check(env)
