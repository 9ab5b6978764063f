"""The contract of the learning law's stages (ilcdob.design.law): every face of every stage agrees.

For each method and each stage kind, on the built-in fleet and on stress fleets unlike it (a
relative-degree-2 plant with sampling zeros near -1, a 43.7 ms fractional input delay, q_order 8,
Ts = 1 ms and 50 ms), on a noisy trial (coloured sensor noise on the error, a learning signal
flown): the law applied in memory, the law read back from its ``filters.json`` entries, its
linear map over the trial and, where the design emits C, the compiled ``learn`` agree to 1e-9 of
the signal's peak; and each stage alone agrees with its own linear map and its own round trip
through ``to_dict``/``from_dict``. A stage registered without a case here fails the coverage test.

Tolerances, of the signal's peak: 1e-9 where two faces run the same coefficients (a stage and its
linear map, the file's law and the compiled C; measured 1e-15 .. 1e-12). 1e-8 between the design in
memory and its file: the closed form runs its zeros and poles (``ZPKFilter``), the file second-order
sections with the stable-inversion series cut at 1e-12; measured 1e-13 .. 1e-11 at 10 ms and 50 ms,
2.2e-9 at 1 ms (an L1 of 63 poles clustered at z = 1, relative degree 2 with q_order 6).
"""

from __future__ import annotations

import shutil
import warnings
from functools import cache

import numpy as np
import pytest
from scipy import signal as sps

from ilcdob.design.law import STAGE_KINDS, LawContext, LearningLaw
from ilcdob.design.law.designed import Designed, file_core
from ilcdob.design.law.laws import law_for
from ilcdob.design.methods import METHODS, MethodSettings
from ilcdob.design.pair import design_pair, fleet_delta_sets
from ilcdob.errors import SpecError
from ilcdob.fleet import default_fleet, fleet_from_dict

from test_c_export import _build_learn, _run_learn

TOL = 1e-9
FILE_TOL = 1e-8

_STRESS_SYSTEMS = [
    {"name": "R2", "plant": {"num": [0.8, 8.0], "den": [1, 4, 0, 0]},
     "controller": {"kp": 1.0, "ki": 0.1, "kd": 1.0, "derivative_filter": 0.05},
     "dob": {"q_order": 6, "q_time_constant": 0.15}, "limits": {"acceleration": 50.0}},
    {"name": "DELAY", "plant": {"num": [10.37568301], "den": [1, 10.32326473, 0, 0]}, "delay": 0.0437,
     "controller": {"kp": 1.2, "ki": 0.12, "kd": 1.53, "derivative_filter": 0.05},
     "dob": {"q_order": 3, "q_time_constant": 0.2}, "limits": {"acceleration": 50.0}},
    {"name": "Q8", "plant": {"num": [10.37568301], "den": [1, 10.32326473, 0, 0]},
     "controller": {"kp": 3.0, "ki": 0.3, "kd": 2.42, "derivative_filter": 0.05},
     "dob": {"q_order": 8, "q_time_constant": 0.15}, "limits": {"acceleration": 50.0}},
]

#: (fleet, source, target, trial seconds) of each pair.
PAIRS = {"built-in": ("built-in", "UAV1", "UAV2", 8.0), "1 ms": ("1 ms", "R2", "DELAY", 3.0),
         "50 ms": ("50 ms", "DELAY", "Q8", 40.0), "1 ms, equal delays": ("1 ms", "R2", "Q8", 3.0)}


@cache
def _fleet(name: str):
    if name == "built-in":
        return default_fleet()
    ts = {"1 ms": 0.001, "50 ms": 0.05}[name]
    return fleet_from_dict({"sample_time": ts, "system": _STRESS_SYSTEMS}, source=f"stress fleet {name}")


def _trial(ts: float, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """A wind-like error (two tones and a gust) with coloured sensor noise, and a learning signal flown."""
    rng = np.random.default_rng(11)
    t = np.arange(int(round(seconds / ts))) * ts
    e = 0.02 * np.sin(0.9 * t + 0.4) + 0.006 * np.sin(4.1 * t) + 0.01 * np.exp(-((t - 0.6 * t[-1]) / 0.5) ** 2)
    e = e * (1.0 - np.exp(-t / 0.5)) ** 3   # from hover: a step at t = 0 through the plant inverse is no wind
    noise = sps.lfilter([1.0], [1.0, -0.9], rng.normal(size=t.size))
    e = e + 1e-6 * noise / np.std(noise)   # 1 um: through the plant inverse (band off) a few m/s^2 at 1 ms
    df = 0.15 * np.sin(0.7 * t + 1.0) * (1.0 - np.exp(-t))
    return e, df


#: (method, bandwidth as a fraction of Nyquist or None, disturbance, law, gain) of each case.
CASES = [("closed-form", None, "command", "paper", 1.0), ("closed-form", 0.05, "airframe", "paper", 1.0),
         ("closed-form", 0.05, "command", "exact-reference", 0.7), ("fir", 0.05, "command", "paper", 1.0),
         ("norm-optimal", None, "command", "paper", 1.0), ("robust", None, "command", "paper", 1.0),
         ("robust-set", 0.05, "command", "paper", 1.0)]
#: Which pairs each method runs on (robust-set: 15 s per design at 10 ms, minutes at 1 ms; the
#: robust SOCP is solved per trial; the norm-optimal linear map is dense, O(N^2) memory).
METHOD_PAIRS = {"closed-form": ["built-in", "1 ms", "50 ms"], "fir": ["built-in", "1 ms", "50 ms"],
                "norm-optimal": ["built-in", "50 ms"],
                "robust": ["built-in"], "robust-set": ["built-in"]}
#: The airframe correction needs equal model delays: its cases fly the pairs that have them.
AIRFRAME_PAIRS = ["built-in", "1 ms, equal delays"]
PARAMS = [(pair, *case) for case in CASES
          for pair in (METHOD_PAIRS[case[0]] if case[2] == "command" else AIRFRAME_PAIRS)]


@cache
def _design(pair: str, method: str, bandwidth: float | None, disturbance: str, law: str):
    fleet_name, src, tgt, seconds = PAIRS[pair]
    fleet = _fleet(fleet_name)
    ts = fleet.sample_time
    e, _ = _trial(ts, seconds)
    t = np.arange(e.size) * ts
    law = law_for(law, 0.5 * (1.0 - np.cos(0.5 * t)), 0.125 * np.cos(0.5 * t))
    chosen = METHODS[method]
    deltas = fleet_delta_sets(fleet, [src, tgt], bound=0.2) if chosen.needs_delta_sets else None
    wc = None if bandwidth is None else bandwidth * np.pi / ts
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return design_pair(fleet, src, tgt, chosen.configured(MethodSettings(n=e.size, deltas=deltas)), band=wc,
                           disturbance=disturbance, law=law)


def _rel(y: np.ndarray, ref: np.ndarray) -> float:
    return float(np.max(np.abs(y - ref)) / np.max(np.abs(ref)))


def _stage_faces(law: LearningLaw, ctx: LawContext, x: tuple[np.ndarray, ...], n: int) -> set[str]:
    """Each stage alone: apply against its linear map and its round trip; returns the kinds seen."""
    seen = set()
    for stage in law.stages:
        seen.add(stage.kind)
        y = stage.apply(x, n, {})
        m, k = x[0].size, len(x)
        assert stage.shape(m, k, n) == (y[0].size, len(y)), stage.kind
        peak = max(np.max(np.abs(v)) for v in y)
        if stage.linear:
            got = stage.linear_map(m, k, n)(np.concatenate(x))
            assert np.max(np.abs(got - np.concatenate(y))) <= TOL * peak, stage.kind
        else:
            with pytest.raises(SpecError, match="no linear map"):
                stage.linear_map(m, k, n)
        back = file_core(stage.to_dict()) if isinstance(stage, Designed) else type(stage).from_dict(stage.to_dict(),
                                                                                                    ctx)
        if back is not None:
            seen.add(back.kind)
            z = back.apply(x, n, {})
            tol = FILE_TOL if isinstance(stage, Designed) else TOL
            assert np.max(np.abs(np.concatenate(z) - np.concatenate(y))) <= tol * peak, stage.kind
        else:
            assert not stage.to_dict() or isinstance(stage, Designed), stage.kind
        if not stage.emits_c:
            with pytest.raises(SpecError, match="C code"):
                stage.c_parts("p_")
        x = y
    return seen


@pytest.mark.parametrize("pair,method,bandwidth,disturbance,law,gain", PARAMS,
                         ids=[f"{p[0]}-{p[1]}-{'band' if p[2] else 'off'}-{p[3]}-{p[4]}-{p[5]}" for p in PARAMS])
def test_every_face_of_the_law_agrees(pair, method, bandwidth, disturbance, law, gain, tmp_path):
    d = _design(pair, method, bandwidth, disturbance, law)
    e, df = _trial(d.filters["sample_time"], PAIRS[pair][3])
    n = e.size
    chain = d.learning_law(gain=gain)
    kinds = [s.kind for s in chain.stages]
    assert ("band in" in kinds) == (bandwidth is not None) and ("airframe path" in kinds) == (disturbance != "command")
    assert ("reference in" in kinds) == (law != "paper") and ("gain" in kinds) == (gain != 1.0) and "limit" in kinds
    y = chain.apply(e, df)
    peak = np.max(np.abs(y))
    assert np.max(np.abs(y - d.learning(e, df, gain=gain).d_f)) <= TOL * peak   # the design's own learning
    ctx = LawContext(reference=d.reference, gain=gain)
    _stage_faces(chain, ctx, (e, df), n)
    # the file: the law read back from its entries alone
    if isinstance(chain.core, Designed) and chain.core.file_form is None:
        with pytest.raises(SpecError, match="no L1/L2"):
            LearningLaw.from_dict(chain.to_dict(), ctx)
        return
    from_file = LearningLaw.from_dict(chain.to_dict(), ctx)
    y_file = from_file.apply(e, df)
    assert np.max(np.abs(y_file - y)) <= FILE_TOL * peak
    if law == "paper" and gain == 1.0:
        assert np.max(np.abs(chain.linear_map(n)(np.concatenate([e, df])) - y)) <= TOL * peak
        assert np.max(np.abs(from_file.linear_map(n)(np.concatenate([e, df])) - y_file)) <= TOL * peak
        cc = shutil.which("cc") or shutil.which("gcc")
        if cc is None:
            pytest.skip("no C compiler")
        got = _run_learn(_build_learn(cc, tmp_path, d.filters), e, df)
        assert np.max(np.abs(got - y_file)) <= TOL * peak
    else:
        with pytest.raises(SpecError, match="no linear map"):
            chain.linear_map(n)


def test_the_limit_clips_in_every_face(tmp_path):
    """Beyond the limit: Python clips with a warning, the file's law the same, C clips and returns 3."""
    d = _design("built-in", "closed-form", 0.05, "command", "paper")
    e, df = _trial(d.filters["sample_time"], PAIRS["built-in"][3])
    unclipped = LearningLaw.from_dict(d.filters, LawContext(on_limit="off")).apply(e, df)
    lim = 0.5 * np.max(np.abs(unclipped))
    filters = {**d.filters, "limit": {**d.filters["limit"], "acceleration_m_s2": lim}}
    with pytest.warns(UserWarning, match="beyond the acceleration limit"):
        y = LearningLaw.from_dict(filters).apply(e, df)
    np.testing.assert_array_equal(y, np.clip(unclipped, -lim, lim))
    refuse = {**filters, "limit": {**filters["limit"], "on_limit": "refuse"}}
    with pytest.raises(Exception, match="refused"):
        LearningLaw.from_dict(refuse).apply(e, df)
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler")
    c_tol = TOL * np.max(np.abs(unclipped))   # C against numpy: the same operations, rounding apart
    np.testing.assert_allclose(_run_learn(_build_learn(cc, tmp_path, filters), e, df, code="3"), y, rtol=0, atol=c_tol)
    (tmp_path / "refuse").mkdir()
    exe = _build_learn(cc, tmp_path / "refuse", refuse)
    np.testing.assert_allclose(_run_learn(exe, e, df, code="4"), unclipped, rtol=0, atol=c_tol)


def test_every_registered_stage_kind_has_a_case():
    seen = set()
    for pair, method, bandwidth, disturbance, law, gain in PARAMS:
        if method in ("robust", "robust-set", "norm-optimal"):
            continue  # their cores are the designed one and the file's robust-set maps, added below
        d = _design(pair, method, bandwidth, disturbance, law)
        e, df = _trial(d.filters["sample_time"], PAIRS[pair][3])
        seen |= _stage_faces(d.learning_law(gain=gain), LawContext(reference=d.reference, gain=gain), (e, df),
                             e.size)
    d = _design("built-in", "robust-set", 0.05, "command", "paper")
    seen.add(file_core(d.filters).kind)
    assert seen == set(STAGE_KINDS), f"stage kinds without a case: {sorted(set(STAGE_KINDS) - seen)}"


def test_a_new_stage_is_one_class_in_one_place(monkeypatch, tmp_path):
    """A stage kind nobody in the library knows (an output trim, written here and registered) flies in every
    face without one line elsewhere: the file's law reads it, its linear map composes and the C ``learn``
    runs it (1e-9 of the peak)."""
    from ilcdob.design.law.stage import CParts, Stage
    from ilcdob.design.maps.finite_horizon import LinearMap

    class Trim(Stage):
        kind, place, keys = "trim", 75, ("trim",)

        def __init__(self, factor: float):
            self.factor = factor

        @classmethod
        def from_dict(cls, filters, ctx):
            return cls(float(filters["trim"])) if "trim" in filters else None

        def to_dict(self):
            return {"trim": self.factor}

        def apply(self, x, n, notes):
            return (self.factor * x[0],)

        def linear_map(self, m, k, n):
            return LinearMap(m, m, lambda v: self.factor * v, lambda v: self.factor * v, "trim")

        def c_parts(self, prefix):
            return CParts(step=f"    for (k = 0; k < n; ++k)\n        df_next[k] *= {self.factor!r};\n",
                          readme="`learn` trims `d_next`.")

    monkeypatch.setitem(STAGE_KINDS, Trim.kind, Trim)
    d = _design("built-in", "closed-form", 0.05, "command", "paper")
    e, df = _trial(d.filters["sample_time"], PAIRS["built-in"][3])
    plain = LearningLaw.from_dict(d.filters).apply(e, df)
    filters = {**d.filters, "trim": 0.5}
    law = LearningLaw.from_dict(filters)
    assert "trim" in [s.kind for s in law.stages]
    y = law.apply(e, df)
    peak = np.max(np.abs(y))
    assert np.max(np.abs(y - 0.5 * plain)) <= TOL * peak
    assert np.max(np.abs(law.linear_map(e.size)(np.concatenate([e, df])) - y)) <= TOL * peak
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler")
    got = _run_learn(_build_learn(cc, tmp_path, filters), e, df)
    assert np.max(np.abs(got - y)) <= TOL * peak
