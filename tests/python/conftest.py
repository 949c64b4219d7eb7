"""Shared by the Python tests: the README blocks' times, printed in pytest's closing summary
(test_readme.py records them), so that CI's log shows what the README costs as it grows."""

import pytest

# (README line, seconds) of every block run.
README_SECONDS = pytest.StashKey[list]()


def pytest_configure(config):
    config.stash[README_SECONDS] = []


def pytest_terminal_summary(terminalreporter, config):
    times = config.stash.get(README_SECONDS, [])
    if times:
        line, longest = max(times, key=lambda t: t[1])
        terminalreporter.write_line(
            f"README.md: {len(times)} blocks ran in {sum(t[1] for t in times):.1f} s "
            f"(the longest, line {line}: {longest:.1f} s)"
        )
