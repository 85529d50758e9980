"""Bad input on the newer surfaces (tests/handsim/fuzz_cases.py): every case is refused clearly.

Output folders, corrupt and truncated shards and manifests, checkpoints (loading and resuming),
every numeric command-line option at NaN / inf / -1e300 (and 1e300 where it is bounded above),
stream files (units, timestamps, nesting, nulls) and the original API's last open cases. Each
case asserts the error's type and its message; ``benchmarks/fuzz_tally.py`` counts the same
list by outcome (also on older code).
"""

import pytest
from fuzz_cases import CLEAR, OTHER_CLEAR, cases, classify, make_fixtures

CASES = cases()


@pytest.fixture(scope="module")
def fixtures(tmp_path_factory):
    """The tiny dataset every data case copies (and the run the resume cases copy)."""
    return make_fixtures(tmp_path_factory.mktemp("fuzz_fixtures"))


def test_the_case_list_covers_every_surface():
    """Each surface of the issue has cases; every numeric option has its four (or three)."""
    surfaces = {c.surface for c in CASES}
    assert surfaces == {
        "output folder",
        "shard",
        "manifest",
        "checkpoint",
        "numeric CLI option",
        "stream",
        "original API",
    }
    numeric = [c for c in CASES if c.surface == "numeric CLI option"]
    assert len(numeric) >= 200
    assert {c.name.rsplit(" ", 1)[1] for c in numeric} == {"nan", "inf", "1e300", "-1e300"}
    assert len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_bad_input_is_refused_with_the_expected_error(case, fixtures, tmp_path):
    """The case ends in its named error (a HandSimError or argparse's usage error) and message."""
    outcome, ok, detail = classify(case, tmp_path, fixtures)
    assert outcome in (CLEAR, OTHER_CLEAR), detail
    assert ok, f"expected {case.expected} matching {case.match!r}; got {detail}"
