"""Validators: the message names the parameter, the value and what is allowed."""

import math

import numpy as np
import pytest

from hapstab.errors import HapstabError, ModelError, check_delay, check_poly, check_real


def test_check_real():
    assert check_real("x", np.float32(2.5)) == 2.5
    with pytest.raises(ModelError, match=r"^mass = -1.0: must be > 0$"):
        check_real("mass", -1.0, positive=True)
    with pytest.raises(ModelError, match="must be finite"):
        check_real("x", math.inf)
    with pytest.raises(ModelError, match="must be a real number"):
        check_real("x", True)


def test_check_delay():
    assert check_delay("n", 4.0) == 4
    with pytest.raises(ModelError, match=r"n = 2.5: must be a whole number of samples >= 0"):
        check_delay("n", 2.5)
    with pytest.raises(ModelError, match="n = -1"):
        check_delay("n", -1)


def test_check_poly():
    np.testing.assert_array_equal(check_poly("p", [0, 0, 1, 2]), [1.0, 2.0])
    np.testing.assert_array_equal(check_poly("p", [0, 0]), [0.0])
    for bad in ([], [1, math.nan], "ab"):
        with pytest.raises(HapstabError, match="p = "):
            check_poly("p", bad)
