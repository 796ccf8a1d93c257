"""Scene values by dotted name."""

import pytest

from vibinverse.errors import VibinverseError


def test_dotted_keys_set_list_elements_like_get_value_reads_them():
    from vibinverse.scene_keys import get_value, set_value

    t = {"m": {"f": [1.0, 2.0], "x": 3.0}}
    set_value(t, "m.f[1]", 5.0)
    set_value(t, "m.f", 7.0)  # a plain key on a list is its first element, as get_value reads it
    set_value(t, "m.x", 4.0)
    assert t == {"m": {"f": [7.0, 5.0], "x": 4.0}} and get_value(t, "m.f") == 7.0
    with pytest.raises(VibinverseError, match=r"m.f\[2\]: index 2 is outside the list of 2 values"):
        set_value(t, "m.f[2]", 1.0)
    with pytest.raises(VibinverseError, match="x is a value, not a table"):
        set_value(t, "m.x.y", 1.0)
