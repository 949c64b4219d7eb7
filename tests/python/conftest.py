"""Shared by the Python tests: the documentation blocks' times (the front page's, the guide's and
the reference pages', run by test_readme.py), printed in pytest's closing summary, so that CI's
log shows what the walk costs as it grows."""

import pytest

# (page and line, seconds) of every block run.
README_SECONDS = pytest.StashKey[list]()


def pytest_configure(config):
    config.stash[README_SECONDS] = []


def pytest_terminal_summary(terminalreporter, config):
    times = config.stash.get(README_SECONDS, [])
    if times:
        where, longest = max(times, key=lambda t: t[1])
        terminalreporter.write_line(
            f"the documentation's blocks: {len(times)} ran in {sum(t[1] for t in times):.1f} s "
            f"(the longest, {where}: {longest:.1f} s)"
        )
