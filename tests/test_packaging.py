"""The distribution ships every package of the source tree (an editable install hides a missing one)."""

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_package_directory_is_listed_in_pyproject():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {
        ".".join(p.parent.relative_to(ROOT).parts)
        for top in ("forward", "vibinverse")
        for p in (ROOT / top).rglob("__init__.py")
    }
    assert found - listed == set(), f"not shipped: {sorted(found - listed)}"
    assert "vibinverse.scenes" in listed  # examples/scenes, mapped in as package data


def test_ci_fails_a_test_skipped_for_a_reason_it_does_not_allow(tmp_path):
    """Under VIBINVERSE_NO_SKIPS=1 (.ci/run) a skip for a missing package or recording fails the run;
    the allowed platform reason does not, and without the variable nothing changes."""
    from tests.conftest import unexpected_skip

    assert unexpected_skip("pyOMA2 is not installed", {"VIBINVERSE_NO_SKIPS": "1"})
    assert not unexpected_skip("this FFmpeg build has no h264 encoder", {"VIBINVERSE_NO_SKIPS": "1"})
    assert not unexpected_skip("pyOMA2 is not installed", {})
    assert "VIBINVERSE_NO_SKIPS=1" in (Path(__file__).resolve().parents[1] / ".ci" / "run").read_text()


def test_the_classifiers_name_the_pythons_that_ci_runs_and_requires_python_starts_at_the_oldest():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    versions = sorted(
        (
            int(c.rsplit(".", 1)[1])
            for c in project["classifiers"]
            if c.startswith("Programming Language :: Python :: 3.")
        ),
    )
    assert project["requires-python"] == f">=3.{versions[0]}"
    ci = (ROOT / ".ci" / "run").read_text()
    assert f"python3.{versions[-1]}" in ci  # the newest classified Python is the one .ci/run tries
