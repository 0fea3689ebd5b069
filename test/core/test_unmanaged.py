"""Unmanaged arrays and views (rcac_ros.core._blocks): the same elements as numpy's views."""

import numpy as np
import pytest

from rcac_ros.core._blocks import unmanaged, unmanaged_block, unmanaged_views
from rcac_ros.core._jit import njit
from rcac_ros.core._packing import CONST_COLS, FILT_COLS, LINK_COLS, STATE_COLS


@njit
def _through_unmanaged(a):
    """Every element of ``unmanaged(a)[1:, 2:5]``, then ``b[0, 0] = -1`` written through it."""
    b = unmanaged(a)[1:, 2:5]
    out = np.empty(b.shape)
    for i in range(b.shape[0]):
        for j in range(b.shape[1]):
            out[i, j] = b[i, j]
    b[0, 0] = -1.0
    return out


@njit
def _block(a, start, rows, cols):
    b = unmanaged_block(a, start, (rows, cols))
    out = np.empty((rows, cols))
    for i in range(rows):
        for j in range(cols):
            out[i, j] = b[i, j]
    return out


@njit
def _views(data, filt, ncols):
    """Columns 0..ncols-1 of the constants and of the state, the scalars and the channels'
    first FILT_COLS columns, read through unmanaged_views."""
    n, const, state, scal, chan = unmanaged_views(data, filt)
    c = np.empty((n, ncols))
    s = np.empty((n, ncols))
    for i in range(n):
        for k in range(ncols):
            c[i, k] = const[i, k]
            s[i, k] = state[i, k]
    ch = np.empty((chan.shape[0], FILT_COLS))
    for a in range(chan.shape[0]):
        for k in range(FILT_COLS):
            ch[a, k] = chan[a, k]
    sc = np.empty(scal.shape[0])
    for k in range(scal.shape[0]):
        sc[k] = scal[k]
    return n, c, s, sc, ch


def test_unmanaged_is_the_same_array():
    a = np.random.default_rng(0).normal(size=(5, 7))
    ref = a[1:, 2:5].copy()
    assert np.array_equal(_through_unmanaged(a), ref)
    assert a[1, 2] == -1.0                    # written through to the owner's data


@pytest.mark.parametrize("start, rows, cols", [(0, 3, 4), (5, 2, 7), (11, 1, 1)])
def test_unmanaged_block_is_a_reshaped_slice(start, rows, cols):
    a = np.random.default_rng(1).normal(size=24)
    ref = a[start:start + rows * cols].reshape((rows, cols))
    assert np.array_equal(_block(a, start, rows, cols), ref)


@pytest.mark.parametrize("n, m", [(1, 1), (7, 3), (12, 12)])
def test_unmanaged_views_are_the_packed_blocks(n, m):
    rng = np.random.default_rng(n + m)
    data = rng.normal(size=(n + 1, LINK_COLS))
    buf = rng.normal(size=(m, n + 1, FILT_COLS))
    ncols = min(CONST_COLS, STATE_COLS)
    got_n, c, s, sc, ch = _views(data, buf, ncols)
    assert got_n == n
    assert np.array_equal(c, data[:n, :ncols])
    assert np.array_equal(s, data[:n, CONST_COLS:CONST_COLS + ncols])
    assert np.array_equal(sc, data[n])
    assert np.array_equal(ch, buf[:, n])
