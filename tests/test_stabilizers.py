"""Stabilizers (`jaxgrid.models.stabilizers`): IEEEST at rest, its transfer function against
scipy.signal, the output limits and cut-out, bad data.

The reference for the dynamics is scipy.signal's simulation of the product of IEEEST's
documented transfer functions (PSS/E: filter, two lead-lags, washout with gain KS), built
here from the CONs with numpy polynomial products: nobody here wrote lsim. The ANDES check
of IEEEST in a grid is `tests/test_simulate.py` (ieee14_ac).
"""
from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import scipy.signal

from conftest import SHARED_CASES
from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import ModelError
from jaxgrid.models.stabilizers import Ieeest, StabilizerPorts
from jaxgrid.records import DyrRecord

ACTIVSG_DYR = SHARED_CASES / "activsg2000" / "ACTIVSg2000_dyn_cmld_zone3_v1.dyr"
AT_REST_TOL = 1e-12  # float64: init and rates evaluate the same expressions
# Heun at DT against the exact response of the linear system: its global error on a mode
# λ is about (λ·DT)²/6 of that mode's amplitude, 9.9e-4 for the fastest here (the Texas
# notch filter's −76.9/s), relative to the response's largest value
DT = 1e-3
RESPONSE_TOL = 1.2e-3

# MODE IB A1-A6 T1-T6 KS LSMAX LSMIN VCU VCL
TEXAS = (1, 0, 1.013, 0.013, 0, 0, 1.013, 0.113, 10, 0.02, 0, 0, 1.65, 1.65, 3, 0.1, -0.1, 0, 0)
FOURTH = (3, 0, 0.2, 0.01, 0.1, 0.004, 0.05, 0.002, 0.3, 0.05, 0.2, 0.1, 2, 2, 0.5, 9, -9, 0,
          0)


def hand(cons, line: int = 1, source: str = "hand.dyr") -> DyrRecord:
    return DyrRecord(model="IEEEST", bus=1, device_id="1", cons=tuple(float(c) for c in cons),
                     icons=(), header=(), record_type="IEEEST", line=line, source=source)


def ports(n: int, dw=0.0, pe=0.8, pm=0.81, ec=1.02) -> StabilizerPorts:
    return StabilizerPorts(*(jnp.full(n, v, dtype=jnp.float64) for v in (dw, pe, pm, ec)))


def transfer_function(c) -> tuple[np.ndarray, np.ndarray]:
    """(numerator, denominator) in descending powers of s, of the unlimited IEEEST from
    its CONs c (A1..VCL)."""
    a1, a2, a3, a4, a5, a6, t1, t2, t3, t4, t5, t6, ks = c[:13]
    num = np.polymul(np.polymul([a6, a5, 1.0], [t1, 1.0]), np.polymul([t3, 1.0], [ks * t5, 0]))
    den = np.polymul(np.polymul([a2, a1, 1.0], [a4, a3, 1.0]),
                     np.polymul(np.polymul([t2, 1.0], [t4, 1.0]), [t6, 1.0]))
    return np.trim_zeros(num, "f"), np.trim_zeros(den, "f")


def test_texas_records_start_at_rest():
    records = read_dyr(ACTIVSG_DYR).by_model("IEEEST")
    assert len(records) == 434
    with jax.enable_x64(True):
        p = Ieeest.prepare(Ieeest.read(records))
        n = len(records)
        inp = ports(n, dw=0.0)
        p, x, *_ = Ieeest.init(p, inp)
        out, dx = Ieeest.rates(p, x, inp)
        assert float(jnp.max(jnp.abs(out))) < AT_REST_TOL, "VOTHSG must be 0 at rest"
        for name, rate in dx.items():
            assert float(jnp.max(jnp.abs(rate))) < AT_REST_TOL, f"d{name}/dt at rest"


@pytest.mark.parametrize("mode", [1, 3, 4, 5])
def test_every_mode_at_rest_with_a_nonzero_input(mode):
    # modes 3-5 read signals that are not zero at rest (Pe 0.8, Pm − Pe 0.01, Ec 1.02)
    cons = (mode,) + FOURTH[1:]
    with jax.enable_x64(True):
        p = Ieeest.prepare(Ieeest.read([hand(cons)]))
        p, x, *_ = Ieeest.init(p, ports(1))
        out, dx = Ieeest.rates(p, x, ports(1))
    assert abs(float(out[0])) < AT_REST_TOL
    assert max(abs(float(d[0])) for d in dx.values()) < AT_REST_TOL


@pytest.mark.parametrize("cons", [TEXAS, FOURTH], ids=["texas-order2", "order4"])
def test_step_response_matches_scipy(cons):
    """A 0.01 p.u. step of the input from rest: Heun at 1 ms against scipy.signal.lsim of
    the documented transfer function (output limits that never bind)."""
    cons = list(cons)
    cons[15:17] = [999.0, -999.0]  # LSMAX, LSMIN: never reached
    step, t_end = 0.01, 3.0
    with jax.enable_x64(True):
        p = Ieeest.prepare(Ieeest.read([hand(cons)]))
        rest = ports(1)
        p, x, *_ = Ieeest.init(p, rest)
        field = {1: "dw", 3: "pe", 4: "pe", 5: "ec"}[int(cons[0])]
        sign = -1.0 if cons[0] == 4 else 1.0  # accelerating power Pm − Pe
        stepped = rest._replace(**{field: getattr(rest, field) + step})

        def heun(x, _):
            y0, k1 = Ieeest.rates(p, x, stepped)
            x1 = {k: x[k] + DT * k1[k] for k in x}
            _, k2 = Ieeest.rates(p, x1, stepped)
            return {k: x[k] + 0.5 * DT * (k1[k] + k2[k]) for k in x}, y0

        n = round(t_end / DT)
        _, out = jax.lax.scan(heun, x, None, length=n)
    t = np.arange(n) * DT
    num, den = transfer_function(cons[2:])
    _, expected, _ = scipy.signal.lsim((num, den), np.full(n, sign * step), t)
    error = np.max(np.abs(np.asarray(out[:, 0]) - expected))
    assert error < RESPONSE_TOL * max(1.0, np.max(np.abs(expected))), \
        f"largest error {error:.3g} (response up to {np.max(np.abs(expected)):.3g})"


def test_output_limits_and_cutout():
    # No filter, both lead-lags bypassed: a speed step of 0.1 reaches the washout at once,
    # whose output KS·T5/T6·(0.1 − x_wo) = 3·0.1 = 0.3 is clipped to LSMAX 0.1; VCU 1.1
    # cuts it out above Ec 1.1, VCL 0.9 below Ec 0.9, and VCU = VCL = 0 never.
    base = (1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1.65, 1.65, 3, 0.1, -0.1)
    records = [hand(base + (1.1, 0.9))] * 3 + [hand(base + (0, 0))]
    with jax.enable_x64(True):
        p = Ieeest.prepare(Ieeest.read(records))
        p, x, *_ = Ieeest.init(p, ports(4))
        inp = ports(4)._replace(dw=jnp.full(4, 0.1), ec=jnp.array([1.0, 1.2, 0.8, 1.2]))
        out, _ = Ieeest.rates(p, x, inp)
    np.testing.assert_allclose(np.asarray(out), [0.1, 0.0, 0.0, 0.1], rtol=0, atol=1e-15)


@pytest.mark.parametrize("cons, pattern", [
    ((2,) + TEXAS[1:], r"ICON MODE = 2: supported input signals 1, 3, 4, 5"),
    ((5, 7) + TEXAS[2:], r"ICON IB = 7 with MODE 5: a remote bus voltage is not modelled"),
    (TEXAS[:2] + (0, 0, 0, 0, 0.5) + TEXAS[7:],
     r"A5 = 0.5, A6 = 0.113: the filter numerator's degree 2 exceeds its denominator's 0"),
    (TEXAS[:2] + (0, 0.013) + TEXAS[4:], r"A1, A2 = 0, 0.013: the filter factor .* not stable"),
    (TEXAS[:9] + (0,) + TEXAS[10:], r"T2 = 0 with T1 = 10: a pure lead is not realisable"),
    (TEXAS[:13] + (0,) + TEXAS[14:], r"CON\(12\) T6 = 0 s: must be > 0"),
    (TEXAS[:15] + (-0.2,) + TEXAS[16:], r"LSMIN = -0.1 > LSMAX = -0.2"),
])
def test_bad_data_names_file_line_and_con(cons, pattern):
    with pytest.raises(ModelError, match=rf"^bad\.dyr:7: IEEEST at bus 1 .*{pattern}"):
        Ieeest.read([hand(cons, line=7, source="bad.dyr")])
