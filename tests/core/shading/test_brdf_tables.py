# SPDX-License-Identifier: GPL-3.0-or-later
"""core.shading.brdf_tables: our quadrature on Cycles' grids against Cycles' own Monte-Carlo
tables (GGX's E and E_avg, the Principled layering albedo), and the look-up as Cycles
interpolates them.  No bpy."""

import pytest

from prt_relight.core.shading import brdf, brdf_tables

from .quadrature import CYCLES_TABLE_GGX_E


# --------------------------------------------------------------------------- #
# Cycles 4.x/5.x Principled BSDF and Multiscatter GGX
# --------------------------------------------------------------------------- #

# Cycles' table_ggx_Eavg[32] (intern/cycles/scene/shader.tables), index = roughness * 31.
CYCLES_TABLE_GGX_EAVG = {
    1: 0.999992, 5: 0.997199, 8: 0.985805, 12: 0.946279, 16: 0.870874,
    20: 0.761345, 24: 0.631068, 28: 0.499191, 31: 0.409137,
}

# Cycles' table_ggx_gen_schlick_ior_s[4096] (16^3, data[z*256 + mu*16 + rough],
# grid value = index / 15 clamped to [1e-4, 1] (z: 0.99); IOR = ior_from_F0(z^4)),
# the Principled layering albedo S(rough, mu, z).  Slices z = 6 (IOR 1.38) and
# z = 7 (IOR 1.56), rows mu = 0, 3, 7, 11, columns rough = 0, 2, 4, 8, 15.
CYCLES_TABLE_GEN_SCHLICK_IOR_S = {
    6: {0: (0.999374, 0.736620, 0.449900, 0.162051, 0.049543),
        3: (0.294528, 0.289595, 0.246073, 0.109290, 0.026967),
        7: (0.055252, 0.055405, 0.055074, 0.039653, 0.011387),
        11: (0.006749, 0.006854, 0.007597, 0.009208, 0.004302)},
    7: {0: (0.999398, 0.744723, 0.463498, 0.173793, 0.055228),
        3: (0.315614, 0.310403, 0.264841, 0.120619, 0.030898),
        7: (0.066236, 0.066340, 0.065506, 0.046703, 0.013620),
        11: (0.008907, 0.009032, 0.009899, 0.011624, 0.005396)},
}


def test_own_tables_match_cycles_tables():
    """Our quadrature on Cycles' grids reproduces Cycles' Monte-Carlo tables."""
    for (row, col), ref in CYCLES_TABLE_GGX_E.items():
        assert brdf_tables.ggx_E_table_column(col)[row] == pytest.approx(ref, abs=5e-4), (row, col)
    for col, ref in CYCLES_TABLE_GGX_EAVG.items():
        assert brdf_tables.ggx_E_avg_node(col) == pytest.approx(ref, abs=5e-4), col
    for iz, rows in CYCLES_TABLE_GEN_SCHLICK_IOR_S.items():
        for row, refs in rows.items():
            for ix, ref in zip((0, 2, 4, 8, 15), refs):
                got = brdf_tables.dielectric_s_table_column(ix, iz)[row]
                assert got == pytest.approx(ref, abs=1e-3), (iz, row, ix, got, ref)


def test_table_interpolation_is_cycles_lookup():
    # node values are returned exactly, midpoints are linear blends (lookup_table_read)
    col = brdf_tables.ggx_E_table_column(10)
    assert brdf.ggx_E(10 / 31, 7 / 31)[()] == pytest.approx(col[7], abs=1e-12)
    mid = brdf.ggx_E(10 / 31, 7.5 / 31)[()]
    assert mid == pytest.approx(0.5 * (col[7] + col[8]), abs=1e-12)
    # E decreases with roughness at normal incidence, E_avg likewise
    assert brdf.ggx_E(0.2, 1.0) > brdf.ggx_E(0.6, 1.0) > brdf.ggx_E(1.0, 1.0)
    assert 1.0 >= brdf.ggx_E_avg(0.0) > brdf.ggx_E_avg(0.5) > brdf.ggx_E_avg(1.0) > 0.4
