import pytest

from .harness import check


@pytest.fixture
def formal(request, tmp_path):
    """``formal(harness, name=, mode=, depth=, expect="pass")`` runs SymbiYosys on ``harness``
    and fails the test unless the result is ``expect`` ("pass" or "fail"). The method, depth
    and solver time go into the test's report (the summary at the end of ``pytest -m formal``)."""
    def run(harness, *, name, mode, depth, expect="pass", **kwargs):
        result = check(harness, name=name, mode=mode, depth=depth,
                       workdir=str(tmp_path / name), **kwargs)
        # a check built to fail (a fault put in, to show the properties bite) says so
        label = "" if expect == "pass" else (
            " (expected: a fault was put in)" if not result.passed else " (a fault was put in, "
            "and it was NOT found)")
        request.node.user_properties.append(("formal", result.summary() + label))
        if expect == "pass":
            assert result.passed, f"{result.summary()}; in {result.workdir}:\n{result.log}"
        else:
            assert not result.passed, f"expected a counterexample: {result.summary()}"
        return result
    return run
