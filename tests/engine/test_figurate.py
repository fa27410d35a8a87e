from math import comb

import numpy as np
import pytest

from engine.errors import InputError
from engine.figurate import MAX_ORDER, outside_matrix, transport_matrix


def test_table_1_of_the_paper():
    # rows T^1..T^5 L_d, columns R^0..R^4 L_d (the paper's row labels from row 3 on are off by one)
    expected = [[1, 1, 1, 1, 1], [1, 2, 3, 4, 5], [1, 3, 6, 10, 15], [1, 4, 10, 20, 35], [1, 5, 15, 35, 70]]
    np.testing.assert_array_equal(transport_matrix(5), expected)


@pytest.mark.parametrize("order", range(1, MAX_ORDER + 1))
def test_appendix_a_recursion(order):
    # c_{r+1}(n) = c_{r+1}(n-1) + c_r(n), c_r(0) = 1 (Eq. 21): T^{r+1} = T · T^r
    m = transport_matrix(order)
    assert (m[:, 0] == 1).all() and (m[0] == 1).all()
    for r in range(1, order):
        for n in range(1, order):
            assert m[r, n] == m[r, n - 1] + m[r - 1, n]


def test_transport_matrix_is_a_power_series_of_t():
    # applying T = Σ R^i to T^r L_d must give T^{r+1} L_d: coefficients are cumulative sums
    m = transport_matrix(6)
    np.testing.assert_array_equal(np.cumsum(m[:-1], axis=1), m[1:])


def test_outside_matrix_has_unreached_light_only_in_the_photograph():
    out = outside_matrix(4)
    np.testing.assert_array_equal(out[:, 0], [1, 0, 0, 0])
    np.testing.assert_array_equal(out[:, 1:], transport_matrix(4)[:, :3])
    np.testing.assert_array_equal(outside_matrix(4, unreached_light=False), transport_matrix(4))
    assert [comb(n + 2, 2) for n in range(3)] == out[2, 1:].tolist()


@pytest.mark.parametrize("bad", [0, -1, MAX_ORDER + 1, 2.5, True, "3"])
def test_bad_orders_are_refused(bad):
    with pytest.raises(InputError, match="order"):
        transport_matrix(bad)
