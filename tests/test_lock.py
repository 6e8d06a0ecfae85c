"""The pinned stack (.ci/requirements.lock) agrees with pyproject.toml: every dependency is locked at one exact
version that its specifier admits, with hashes, and nothing is locked that nothing asks for."""

import re
import tomllib
from pathlib import Path

from packaging.markers import default_environment
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / ".ci" / "requirements.lock"
BUILD_IN = ROOT / ".ci" / "build-requirements.in"
# the lock is made for CPython 3.11 on Linux x86_64 (.ci/lock); markers are evaluated there
LOCK_ENV = {**default_environment(), "platform_system": "Linux", "platform_machine": "x86_64", "sys_platform": "linux",
            "python_version": "3.11", "python_full_version": "3.11.7", "implementation_name": "cpython"}


def _lock_entries():
    """{canonical name: (version, number of hashes, the packages it is there for)} from the lock."""
    out, name = {}, None
    for line in LOCK.read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9._-]+)==([^ \\]+)", line)
        if m:
            name = canonicalize_name(m.group(1))
            out[name] = [m.group(2), 0, set()]
        elif name and line.strip().startswith("--hash=sha256:"):
            out[name][1] += 1
        elif name and re.match(r"^\s+#\s+(via\s+)?[A-Za-z0-9-]", line):
            out[name][2].add(line.strip().removeprefix("#").strip().removeprefix("via").strip())
    return out


def _direct_requirements():
    proj = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = list(proj["dependencies"]) + list(proj["optional-dependencies"]["test"])
    reqs += [ln.strip() for ln in BUILD_IN.read_text().splitlines() if ln.strip() and not ln.startswith("#")]
    return [Requirement(r) for r in reqs]


def test_every_dependency_is_locked_at_a_version_it_admits():
    lock = _lock_entries()
    assert lock, f"no pinned entries in {LOCK}"
    checked = 0
    for req in _direct_requirements():
        if req.marker is not None and not req.marker.evaluate(LOCK_ENV):
            continue  # e.g. open3d (not open3d-cpu) off Linux x86_64
        name = canonicalize_name(req.name)
        assert name in lock, f"{req} (pyproject.toml) is not in {LOCK.name}: run `bash .ci/lock`"
        version = Version(lock[name][0])
        assert req.specifier.contains(version, prereleases=True), (
            f"{LOCK.name} pins {name}=={version}, outside pyproject.toml's {req}: run `bash .ci/lock`")
        checked += 1
    assert checked >= 10


def test_every_locked_package_has_hashes_and_a_reason():
    """--require-hashes installs need a hash per package; a package nobody asks for is stale."""
    for name, (version, n_hashes, via) in _lock_entries().items():
        assert n_hashes >= 1, f"{name}=={version} has no --hash in {LOCK.name}"
        assert via, f"{name}=={version} is in {LOCK.name} but nothing requires it: run `bash .ci/lock`"


def test_setup_installs_from_the_lock():
    setup = (ROOT / ".ci" / "setup").read_text()
    assert "--require-hashes" in setup and ".ci/requirements.lock" in setup
    assert "--no-deps" in setup  # nothing unpinned is pulled in beside the lock
    run = (ROOT / ".ci" / "run").read_text()
    readme = (ROOT / "README.md").read_text()
    test_cmd = re.search(r"bash \.ci/setup && \.venv/bin/python -m pytest[^\n`]*", readme)
    assert test_cmd and test_cmd.group(0) in run, "the README's test command is what .ci/run runs"
