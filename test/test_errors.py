"""The exception hierarchy's message helper: values shown in bounded length."""

import time

from panel_deploy.errors import SHOWN_LENGTH, shown


def test_shown_is_repr_for_small_values():
    for value in ("abc", 0.5, None, [1, [2, "x"]], {"k": (1, 2)}):
        assert shown(value) == repr(value)


def test_shown_stays_short_for_any_value():
    huge = ["x" * 10**6]
    for _ in range(30):  # 10^30 leaves once written out, by shared references
        huge = [huge] * 10
    values = (huge, "y" * 10**7, {str(i): i for i in range(10**5)}, 10**5000 // 7)
    start = time.perf_counter()
    for value in values:
        text = shown(value)
        assert len(text) <= SHOWN_LENGTH and "\n" not in text, text
    assert time.perf_counter() - start < 0.5
    assert shown(10**5000 // 7) == "<an integer of about 5000 digits>"  # repr would raise
