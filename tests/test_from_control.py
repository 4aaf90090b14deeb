"""``from_control`` is the inverse of ``to_control`` and of ``(L1, H, L2)`` for every member.

Models: the reference stage (:mod:`hystid.reference`), each member identified on a record of
:func:`hystid.testing.stage_a_like` (a Bouc-Wen stage simulated independently of the model
code, with a rest level and a sensor offset), and, where ``../shared/data`` is present, the
member ``identify`` chooses on measured stage A (a ``pi-stage`` PI sandwich). Each is read back
from its interconnected system and from its three blocks, by its own class and by
:class:`~hystid.sandwich.Sandwich`, and must simulate like the model on a held-out input; the
README's Python lines run on each member.
"""

from __future__ import annotations

import copy
import re
import warnings
from pathlib import Path
from types import SimpleNamespace

import control as ct
import numpy as np
import pytest

import hystid
from hystid.identify import identify
from hystid.mduhem import MultiDuhemSandwich
from hystid.model import DuhemSandwich, Structure
from hystid.pi import PISandwich, PIStructure
from hystid.records import load_record
from hystid.reference import paper_excitation, reference_model
from hystid.sandwich import Sandwich
from hystid.testing import stage_a_like

ROOT = Path(__file__).resolve().parents[1]
STAGE_A = ROOT.parent / "shared" / "data" / "real" / "stageA"
NAMES = ("duhem", "gduhem", "pi", "pi-stage", "mduhem")
CLASSES = (DuhemSandwich, PISandwich, MultiDuhemSandwich)


@pytest.fixture(scope="module")
def identified() -> dict[str, Sandwich]:
    """Every member identified on one record of the independent stage-A-like simulator."""
    rec = stage_a_like("prbn", seconds=1.0, rest_seconds=0.5, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {name: identify(rec, model=name).model for name in NAMES}


def held_out(model: Sandwich) -> np.ndarray:
    """An input the model was not identified on (another seed of its stage)."""
    if model.fs == 30_000.0:
        return paper_excitation(3000, seed=7)
    return stage_a_like("prbn", seconds=0.5, rest_seconds=0.2, seed=1).u


def assert_simulates_like(back: Sandwich, model: Sandwich, u: np.ndarray) -> None:
    y = model.simulate(u, check=False).y
    err = np.max(np.abs(back.simulate(u, check=False).y - y))
    assert err <= 1e-9 * np.max(np.abs(y)), f"{err:.3g} off on a range of {np.ptp(y):.3g}"


def models(identified: dict[str, Sandwich]) -> dict[str, Sandwich]:
    return {"reference": reference_model(), **identified}


def test_identified_members_are_the_ones_asked_for(identified):
    kinds = {name: type(m) for name, m in identified.items()}
    assert kinds == {"duhem": DuhemSandwich, "gduhem": DuhemSandwich, "pi": PISandwich,
                     "pi-stage": PISandwich, "mduhem": MultiDuhemSandwich}
    for m in identified.values():  # placed: the round trip must carry the placement
        assert m.u_rest != 0.0 and m.offset != 0.0
    assert identified["duhem"].rest_memory != 0.0


@pytest.mark.parametrize("way", ["system", "blocks"])
@pytest.mark.parametrize("reader", ["member", "base"])
@pytest.mark.parametrize("name", ("reference", *NAMES))
def test_round_trip_simulates_like_the_model(identified, name, way, reader):
    model = models(identified)[name]
    cls = type(model) if reader == "member" else Sandwich
    back = (cls.from_control(model.to_control()) if way == "system"
            else cls.from_control(model.L1, model.H, model.L2))
    assert type(back) is type(model)
    assert back.structure == model.structure
    assert (back.u_rest, back.offset, back.fs) == (model.u_rest, model.offset, model.fs)
    assert getattr(back, "rest_memory", None) == getattr(model, "rest_memory", None)
    for fixed in ("thresholds", "rates"):
        if hasattr(model, fixed):
            np.testing.assert_allclose(getattr(back, fixed), getattr(model, fixed), rtol=1e-12)
    np.testing.assert_allclose(back.theta, model.theta, rtol=1e-9, atol=1e-12)
    assert_simulates_like(back, model, held_out(model))
    if way == "system":
        assert back.name == model.name


@pytest.mark.parametrize("name", NAMES)
def test_like_takes_what_the_blocks_do_not_hold(identified, name):
    model = copy.copy(identified[name])
    model.units = {"u": "kV", "y": "nm"}
    plain = Sandwich.from_control(model.to_control())
    assert plain.envelope is None and plain.units == {"u": "V", "y": "um"}
    back = Sandwich.from_control(model.L1, model.H, model.L2, like=model)
    assert back.envelope == model.envelope and back.units == {"u": "kV", "y": "nm"}
    assert back.name == model.name and back.structure == model.structure
    u = held_out(model)
    assert_simulates_like(back, model, u)
    # an explicit placement overrides the blocks'
    moved = type(model).from_control(model.to_control(), offset=model.offset + 1.0)
    np.testing.assert_allclose(moved.simulate(u, check=False).y,
                               model.simulate(u, check=False).y + 1.0, rtol=0, atol=1e-9)


def test_structure_with_a_zero_last_coefficient_is_kept_by_like():
    s = PIStructure(n_operators=3, n1a=1, n1b=1, n2a=2, n2b=2, q1=0, q2=1)
    values = {"a11": -0.4, "mu0": 0.8, "mu1": 0.3, "mu2": 0.1, "a21": -0.9, "a22": 0.0,
              "b22": 0.2}
    model = PISandwich(values, [0.0, 0.5, 1.0], s, fs=1000.0, u_rest=2.0, offset=-1.0)
    read = PISandwich.from_control(model.to_control())
    assert read.structure == PIStructure(3, 1, 1, 1, 2, 0, 1)  # a22 = 0: one order lower
    u = 2.0 + np.sin(np.linspace(0.0, 12.0, 400)) * np.linspace(0.0, 1.5, 400)
    assert_simulates_like(read, model, u)
    assert PISandwich.from_control(model.to_control(), like=model).structure == s
    assert PISandwich.from_control(model.to_control(), structure=s).structure == s


@pytest.mark.parametrize("name", NAMES)
def test_the_wrong_class_says_which_class_reads_the_system(identified, name):
    model = identified[name]
    owner = type(model)
    for cls in CLASSES:
        if cls is owner:
            continue
        for args in ((model.to_control(),), (model.L1, model.H, model.L2)):
            with pytest.raises(ValueError) as err:
                cls.from_control(*args)
            message = str(err.value)
            assert f"{owner.__module__}.{owner.__name__}" in message
            assert "Sandwich.from_control" in message
            assert not re.search(r"sys\[\d+\]", message)
    words = {PISandwich: "Prandtl-Ishlinskii", MultiDuhemSandwich: "Duhem operators in parallel",
             DuhemSandwich: "Duhem block"}
    other = DuhemSandwich if owner is not DuhemSandwich else PISandwich
    with pytest.raises(ValueError, match=words[owner]):
        other.from_control(model.to_control())


def test_errors_name_what_was_expected():
    model = reference_model()
    with pytest.raises(ValueError, match="expected the blocks L1, H and L2"):
        Sandwich.from_control(model.L1)
    with pytest.raises(ValueError, match="hysteresis block, a discrete control.NonlinearIOSystem"):
        Sandwich.from_control(model.L1, model.L2, model.L2)
    gain = ct.nlsys(None, lambda t, x, u, p: p["k"] * u, inputs=["w1"], outputs=["w2"],
                    params={"k": 2.0}, dt=model.dt, name="H")
    with pytest.raises(ValueError, match="hysteresis block of a hystid member.*'k'"):
        Sandwich.from_control(model.L1, gain, model.L2)
    with pytest.raises(TypeError, match="unknown options \\['prefix'\\].*f0"):
        DuhemSandwich.from_control(model.to_control(), prefix="pi")
    with pytest.raises(TypeError, match="expected a Structure for DuhemSandwich"):
        DuhemSandwich.from_control(model.to_control(), structure=PIStructure())
    with pytest.raises(ValueError, match="like: expected a DuhemSandwich"):
        Sandwich.from_control(model.to_control(), like=_pi_model())
    with pytest.raises(ValueError, match="L1: does not fit the structure"):
        DuhemSandwich.from_control(model.to_control(), structure=Structure(n1a=0))
    with pytest.raises(ValueError, match="share one discrete dt"):
        DuhemSandwich.from_control(model.L1, model.H, reference_model(fs=10_000.0).L2)


def _pi_model() -> PISandwich:
    s = PIStructure(n_operators=2, n1a=0, n1b=1, q1=0, n2a=1, n2b=1)
    return PISandwich({"mu0": 1.0, "mu1": 0.2, "a21": -0.5}, [0.0, 0.4], s)


def _readme_lines() -> str:
    """The README's Python lines that use ``model`` (from ``model = result.model`` on, the
    saved-model line left out: it reads a file)."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```python\nimport control as ct\nimport hystid\n(.*?)```", text, re.S)
    assert block, "README: the python-control snippet is gone"
    code = block.group(1)
    start = code.index("model = result.model")
    return "\n".join(line for line in code[start:].splitlines() if "load_model" not in line)


@pytest.mark.parametrize("name", ("reference", *NAMES))
def test_readme_lines_hold_for_every_member(identified, name):
    model = models(identified)[name]
    u = held_out(model)[:1500]
    rec = SimpleNamespace(t=np.arange(len(u)) / model.fs, u=u)
    space = {"ct": ct, "hystid": hystid, "rec": rec, "result": SimpleNamespace(model=model)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        exec(compile(_readme_lines(), "README.md", "exec"), space)  # noqa: S102
    assert isinstance(space["model"], hystid.sandwich.Sandwich)
    assert all(isinstance(b, ct.TransferFunction) and b.dt == model.dt
               for b in (model.L1, model.L2))
    assert isinstance(model.H, ct.NonlinearIOSystem) and model.H.dt == model.dt
    fast = space["fast"].y
    scale = np.max(np.abs(fast))
    assert np.max(np.abs(space["resp"].outputs[0] - fast)) <= 1e-9 * scale
    for key in ("back", "same"):
        assert type(space[key]) is type(model)
        assert_simulates_like(space[key], model, u)


@pytest.mark.skipif(not (STAGE_A / "prbn_1.csv").exists(),
                    reason=f"measured stage A not found: {STAGE_A} (../shared/data beside the "
                           "checkout)")
def test_measured_stage_a_default_member_round_trip():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = identify(load_record(STAGE_A / "prbn_1.csv")).model
    assert isinstance(model, PISandwich)
    assert model.structure == PIStructure(n_operators=20, n1a=0, n1b=1, q1=0, n2a=3, n2b=3,
                                          q2=1)
    u = load_record(STAGE_A / "prbn_2.csv").u  # held out: the other record
    for back in (PISandwich.from_control(model.L1, model.H, model.L2),
                 PISandwich.from_control(model.to_control()),
                 Sandwich.from_control(model.to_control())):
        assert back.structure == model.structure
        assert (back.u_rest, back.offset) == (model.u_rest, model.offset)
        assert_simulates_like(back, model, u)
