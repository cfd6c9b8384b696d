"""The FileCheck-style helper itself must fail on mismatches."""

import pytest

TEXT = "a = 1\nb = 2\nc = 3\n"


def test_check_in_order_and_next(check_ir):
    check_ir(TEXT, "CHECK: a = 1\nCHECK-NEXT: b = 2\nCHECK: c = {{[0-9]}}")


@pytest.mark.parametrize("checks", ["CHECK: c\nCHECK: a", "CHECK: a\nCHECK-NEXT: c",
                                    "CHECK-NOT: b\nCHECK: c", "CHECK: zzz"])  # fmt: skip
def test_check_failures(check_ir, checks):
    with pytest.raises(pytest.fail.Exception):
        check_ir(TEXT, checks)
