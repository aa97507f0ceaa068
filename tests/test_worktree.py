"""The check that the suite leaves the working tree as it found it (tests/conftest.py)."""

import shutil
import subprocess

import pytest

from tests.worktree import changes, tree_status

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="needs git")


def git(repo, *args):
    subprocess.run(["git", *args], cwd=repo, check=True, capture_output=True)


@pytest.fixture
def repo(tmp_path):
    git(tmp_path, "init", "-q")
    (tmp_path / ".gitignore").write_text("out/\n")
    (tmp_path / "tracked.txt").write_text("a\n")
    git(tmp_path, "add", ".")
    git(tmp_path, "-c", "user.name=t", "-c", "user.email=t@t", "commit", "-qm", "start")
    return tmp_path


def test_a_file_written_by_a_run_is_a_change_even_when_ignored(repo):
    (repo / "tracked.txt").write_text("a developer's local edit\n")  # before the run: fine
    (repo / "notes.txt").write_text("untracked before the run\n")
    before = tree_status(repo)
    assert changes(before, tree_status(repo)) == []

    (repo / "MUJOCO_LOG.TXT").write_text("WARNING\n")
    (repo / "out").mkdir()
    (repo / "out" / "report.json").write_text("{}")
    assert changes(before, tree_status(repo)) == ["!! out/", "?? MUJOCO_LOG.TXT"]


def test_caches_and_edits_made_before_the_run_are_not_changes(repo):
    (repo / "tracked.txt").write_text("edited\n")
    before = tree_status(repo)
    for cache in ("__pycache__", ".hypothesis", ".pytest_cache"):
        (repo / "pkg" / cache).mkdir(parents=True)
        (repo / "pkg" / cache / "x.pyc").write_bytes(b"")
    assert changes(before, tree_status(repo)) == []
    (repo / "tracked.txt").unlink()
    assert changes(before, tree_status(repo)) == [" D tracked.txt"]


def test_outside_a_git_tree_there_is_nothing_to_compare(tmp_path):
    assert tree_status(tmp_path) is None
