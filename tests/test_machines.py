"""Synchronous machine models: saturation curve, initialisation at rest, Norton consistency.

Parameters come from real DYR files (ANDES's ieee14 GENROU, the PNNL 39-bus GENSAL and
GENCLS records); the operating point is a typical lagging one.
"""
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxgrid.io.dyr import read_dyr
from jaxgrid.models.base import ModelError, quadratic_saturation, quadratic_saturation_constants
from jaxgrid.models.machines import MACHINES, MachinePorts, MachineStart
from jaxgrid.records import DyrRecord
from tests.conftest import SHARED_CASES, andes_cases_dir

V0 = 1.02 * np.exp(0.2j)   # terminal voltage, p.u.
I0 = 0.8 - 0.3j            # injected current, p.u. MBASE (P = 0.87, Q = 0.27 at V0 angle 0)
OMEGA_B = 2 * np.pi * 60


def _records(path, model):
    data = read_dyr(path)
    return list(data.by_model(model))


@pytest.fixture(scope="module")
def machine_records(tmp_path_factory):
    from experiments.reference.andes_files import write_psse_dyr
    ieee14 = write_psse_dyr(str(andes_cases_dir() / "ieee14/ieee14.dyr"),
                            str(tmp_path_factory.mktemp("m") / "ieee14.dyr"))
    gensal = _records(SHARED_CASES / "ieee39/IEEE39bus_3AC_exdc1_gridpack.dyr", "GENSAL")
    genrou = _records(ieee14, "GENROU")
    rename = lambda rs, name: [DyrRecord(**{**r.__dict__, "model": name}) for r in rs]  # noqa
    return {"GENROU": genrou, "GENSAL": gensal,
            "GENCLS": _records(SHARED_CASES / "ieee39/IEEE39bus_3AC.dyr", "GENCLS"),
            "GENROE": rename(genrou, "GENROE"), "GENSAE": rename(gensal, "GENSAE")}


def _initialised(name, records):
    model = MACHINES[name]
    p = model.read(records)
    n = len(records)
    p.update(ra=np.full(n, 0.002), zx=np.full(n, 0.25))
    p["xs"] = np.asarray(model.source_reactance(p), dtype=float)
    p = {k: jnp.asarray(v) for k, v in model.prepare(p).items()}
    v0, i0 = jnp.full(n, V0), jnp.full(n, I0)
    p, x, out, *_ = model.init(p, MachineStart(v0, i0))
    efd0, pm0 = out["efd"], out["pm"]
    return model, p, x, efd0, pm0, v0, i0


def test_quadratic_saturation_passes_through_its_points():
    a, b = quadratic_saturation_constants(1.0, 0.09, 1.2, 0.38)
    with jax.enable_x64(True):
        se = quadratic_saturation(jnp.array([1.0, 1.2, a - 0.01]), a, b)
    np.testing.assert_allclose(np.asarray(se), [0.09, 0.38, 0.0], atol=1e-12)
    a, b = quadratic_saturation_constants(1.0, 0.0, 1.2, 0.2)  # S1 = 0 < S2: A = X1
    assert a == pytest.approx(1.0) and b == pytest.approx(0.2 * 1.2 / 0.2 ** 2)


@pytest.mark.parametrize("name", ["GENCLS", "GENROU", "GENSAL", "GENROE", "GENSAE"])
def test_machine_starts_at_rest(name, machine_records):
    with jax.enable_x64(True):
        model, p, x, efd0, pm0, v0, i0 = _initialised(name, machine_records[name])
        # the Norton source reproduces the power-flow point
        np.testing.assert_allclose(np.asarray(model.emf(p, x) - (p["ra"] + 1j * p["xs"]) * i0),
                                   np.asarray(v0), atol=1e-12)
        # Pm0 = P + Ra·|I|² (air-gap power)
        expected = np.real(V0 * np.conj(I0)) + 0.002 * abs(I0) ** 2
        np.testing.assert_allclose(np.asarray(pm0), expected, atol=1e-12)
        _, dx = model.rates(p, x, MachinePorts(model.to_rotor(x, i0), efd0, pm0, OMEGA_B))
        for state, rate in dx.items():
            assert np.abs(np.asarray(rate)).max() < 1e-10, f"{name}: d{state}/dt != 0 at t = 0"


def test_unsaturated_genrou_angle_is_the_textbook_one(machine_records):
    """Without saturation, δ0 = arg(V + (Ra + jXq)·I) (q-axis EMF position)."""
    records = [DyrRecord(**{**r.__dict__, "cons": r.cons[:12] + (0.0, 0.0)})
               for r in machine_records["GENROU"]]
    with jax.enable_x64(True):
        _, p, x, *_ = _initialised("GENROU", records)
        expected = np.angle(V0 + (0.002 + 1j * np.asarray(p["xq"])) * I0)
        np.testing.assert_allclose(np.asarray(x["delta"]), expected, atol=1e-12)


def test_bad_reactance_order_names_the_record(machine_records):
    bad = machine_records["GENROU"][0]
    cons = list(bad.cons)
    cons[10] = cons[8] + 0.1  # X''d above X'd
    with pytest.raises(ModelError, match=rf"ieee14.dyr:{bad.line}: GENROU at bus {bad.bus}.*X''d"):
        MACHINES["GENROU"].read([DyrRecord(**{**bad.__dict__, "cons": tuple(cons)})])
