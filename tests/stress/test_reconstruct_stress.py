"""Property-based stress tests of the numpy reconstruction (modes paper,
fast, refine, idpass) on generated ground-truth fields.

Every property is its own test, parametrised by mode, so that failures are
itemised.  Profiles (``fast`` by default, ``thorough`` with
``MITSUBA_MRT_STRESS=thorough``) are set in conftest.py.  A failing example
prints a standalone reproduction (hypothesis' notes).

The bodies of the ``@property_test`` tests hold no ``assert``: each returns
``(problems, measure)``, a list of what is wrong (empty: the property holds)
and how bad the worst is; the decorator runs it per mode and example through
:func:`.stress_support.check`, which fails the example when the list is not
empty (``thorough``: counts it, and :func:`.stress_support.finish` fails the
test at the end).  The ``test_known_*`` regressions below assert as usual.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from mitsuba_mrt import MRTError, MRTParams, SparseTrace, grid_pattern, reconstruct

from .stress_support import (CONSTANT_ALBEDOS, MODES, VALUES, Case, bound_tolerance,
                             cases, check, degenerate_cases, finish, ratio, region_samples)


#: Mode paper keeps the report's Algorithm 2, whose smoothing dilates the ids
#: one after the other in increasing order: a larger id grows over a smaller
#: one, traced pixels included, so the result depends on the numbering.  Mode
#: fast dilates them in an order the samples decide and keeps traced ids.
PAPER_ALGORITHM_2 = ("mode paper keeps the report's Algorithm 2: its smoothing dilates "
                     "the ids in increasing order, over traced pixels and by number")


def property_test(prop, strategy, exceptions=None):
    """A test of ``prop`` per mode; ``body(case, mode, data) -> (problems, measure)``.

    ``body`` asserts nothing: the test fails where its ``problems`` are not
    empty (:func:`.stress_support.check`).  ``exceptions``: ``{mode: reason}`` for modes that document why the
    property does not hold for them (they are skipped, with the reason).
    """
    exceptions = exceptions or {}

    def decorate(body):
        @pytest.mark.parametrize("mode", MODES)
        def test(mode):
            if mode in exceptions:
                pytest.skip(exceptions[mode])

            @given(case=strategy, data=st.data())
            def inner(case, data):
                check(prop, mode, case, lambda: body(case, mode, data))
            inner()
            finish(prop, mode)
        test.__name__ = body.__name__
        test.__doc__ = body.__doc__
        return test
    return decorate


def _regions(out):
    return np.unique(out.ids).tolist()


# --------------------------------------------------------------------------- properties
# No assert in these bodies: the returned problems are the verdict (property_test
# fails the example when the list is not empty).

@property_test("finite", cases(values=VALUES + ("huge",), exponents=(-30, 37)))
def test_finite_output(case, mode, data):
    """Finite input (values up to float32's largest, albedo down to 1e-5) gives
    finite output, or a clear MRTError."""
    try:
        out = case.run(mode)
    except MRTError:
        return [], 0.0
    bad = ~np.isfinite(out.image)
    if bad.any():
        vals = out.image[bad]
        return [f"non-finite: {int(bad.any(-1).sum())} of {bad.shape[0] * bad.shape[1]} pixels "
                f"(nan {int(np.isnan(vals).sum())}, inf {int(np.isinf(vals).sum())}); "
                f"input max {case.field.radiance.max():.3g}"], float(bad.mean())
    return [], 0.0


@property_test("traced_exact", cases())
def test_traced_pixels_are_exact(case, mode, data):
    """Traced pixels (grid and any extra traced) come back bit for bit."""
    out = case.run(mode)
    mask = out.traced_mask
    want = case.field.radiance[mask]
    got = out.image[mask]
    diff = got != want
    if diff.any():
        rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-300)
        return [f"traced pixels differ: {int(diff.any(-1).sum())} of {int(mask.sum())}, "
                f"max relative {rel[diff].max():.3g} (image dtype {out.image.dtype})"], float(rel.max())
    return [], 0.0


@property_test("traced_ids", cases(), exceptions={"paper": PAPER_ALGORITHM_2})
def test_traced_ids_are_kept(case, mode, data):
    """The output id map gives every traced pixel the id it was traced with
    (the regions the other properties use are the output's)."""
    out = case.run(mode)
    truth = case.field.ids(case.params.rule_for(mode))
    mask = out.traced_mask
    wrong = out.ids[mask] != truth[mask]
    if wrong.any():
        return [f"traced ids overwritten: {int(wrong.sum())} of {int(mask.sum())} traced pixels"], \
            float(wrong.mean())
    return [], 0.0


@property_test("no_new_extremes", cases(albedos=CONSTANT_ALBEDOS))
def test_no_new_extremes(case, mode, data):
    """Every pixel lies within [min, max] of the samples of its own id (the
    output id map's), per channel; albedo is constant within each id, so
    radiance is what is interpolated.  Traced pixels are left to
    test_traced_pixels_are_exact."""
    out = case.run(mode)
    samples = region_samples(case, mode, out)
    problems, worst = [], 0.0
    for region in _regions(out):
        if region not in samples:
            continue
        s = samples[region]
        lo, hi = s.min(0), s.max(0)
        tol = bound_tolerance(lo, hi)
        pix = out.image[(out.ids == region) & ~out.traced_mask]
        over = np.maximum(pix - hi - tol, lo - tol - pix)
        if (over > 0).any() or not np.isfinite(pix).all():
            p, ch = np.unravel_index(np.nanargmax(np.where(np.isfinite(over), over, np.inf)),
                                     over.shape)
            span = hi[ch] - lo[ch]
            excess = ratio(over[p, ch] + tol[ch], span) if span > 0 else np.inf
            # the measure: how far out, relative to the larger of range and magnitude
            worst = max(worst, ratio(over[p, ch] + tol[ch], max(span, abs(lo[ch]), abs(hi[ch]))))
            problems.append(
                f"out of range: id {region} ({len(s)} samples): value {pix[p, ch]:.6g} outside "
                f"[{lo[ch]:.6g}, {hi[ch]:.6g}] (channel {ch}) by {excess:.3g} x the range, "
                f"{ratio(pix[p, ch], hi[ch]):.3g} x the max, "
                f"{int((over > 0).any(-1).sum())} of {len(pix)} pixels out")
    return problems, worst


@property_test("scale_invariance", cases(exponents=(0, 0)))
def test_scale_invariance(case, mode, data):
    """reconstruct(k v) == k reconstruct(v), relative 1e-5 of the image's maximum,
    for k in 1e-30 .. 1e30 (k v stays inside float32's normal range)."""
    e = data.draw(st.integers(-30, 30), label="exponent of k")
    m = data.draw(st.floats(1.0, 9.9), label="mantissa of k")
    fld = case.field
    safe = np.where(fld.albedo > 1e-6, fld.albedo, 1.0)
    top = float((fld.radiance / safe).max())
    if top > 0:  # keep k * radiance / albedo below 1e37 (no float32 overflow)
        e = min(e, int(np.floor(np.log10(1e37 / (m * top)))))
    k = m * 10.0 ** e
    base = case.run(mode)
    scaled = case.run(mode, fld.with_radiance(fld.radiance * k))
    if not np.array_equal(base.ids, scaled.ids):
        return [f"ids change with the scale (k={k:.3g})"], 1.0
    ref = k * base.image
    top = np.abs(ref).reshape(-1, 3).max(0)
    err = np.abs(scaled.image - ref)
    tol = 1e-5 * top + 1e-300
    if (err > tol).any() or not np.isfinite(err).all():
        rel = float(np.nanmax(np.where(np.isfinite(err), err, np.inf) / np.where(top > 0, top, 1e-300)))
        return [f"not scale invariant: k={k:.3g}: max error {rel:.3g} of the image max, "
                f"{int((err > tol).any(-1).sum())} of {err.shape[0] * err.shape[1]} pixels"], rel
    return [], 0.0


@property_test("relabel_invariance", cases(), exceptions={"paper": PAPER_ALGORITHM_2})
def test_relabel_invariance(case, mode, data):
    """Permuting the (non-background) shape labels leaves the image unchanged."""
    fld = case.field
    labels = np.unique(fld.shape_index[fld.shape_index > 0])
    new = np.array(data.draw(st.lists(st.integers(1, 1000), min_size=len(labels),
                                      max_size=len(labels), unique=True), label="new labels"))
    table = np.zeros(int(fld.shape_index.max()) + 1, np.int64)
    table[labels] = new
    base = case.run(mode)
    other = case.run(mode, fld.with_shapes(table[fld.shape_index]))
    top = np.abs(base.image).reshape(-1, 3).max(0)
    err = np.abs(other.image - base.image)
    tol = 1e-6 * top + 1e-300
    if (err > tol).any() or not np.isfinite(err).all():
        rel = float(np.nanmax(np.where(np.isfinite(err), err, np.inf) / np.where(top > 0, top, 1e-300)))
        return [f"relabelling changes the image: {int((err > tol).any(-1).sum())} pixels, "
                f"max change {rel:.3g} of the image max (labels {labels.tolist()} -> "
                f"{new.tolist()})"], float((err > tol).any(-1).mean())
    return [], 0.0


@property_test("constant_region", cases(values=("perid", "constant", "zero", "mixed"),
                                        albedos=CONSTANT_ALBEDOS))
def test_constant_regions_stay_constant(case, mode, data):
    """An id whose samples are all equal is that value at every one of its pixels."""
    out = case.run(mode)
    samples = region_samples(case, mode, out)
    problems, worst = [], 0.0
    for region in _regions(out):
        s = samples.get(region)
        if s is None or not (s == s[0]).all():
            continue
        c = s[0]
        pix = out.image[(out.ids == region) & ~out.traced_mask]
        dev = np.abs(pix - c)
        tol = 1e-5 * np.abs(c) + 1e-300
        if (dev > tol).any() or not np.isfinite(pix).all():
            rel = float(np.nanmax(np.where(np.isfinite(dev), dev, np.inf) / np.maximum(np.abs(c), 1e-300)))
            worst = max(worst, rel)
            p = int(np.nanargmax(np.where(np.isfinite(dev), dev, np.inf).max(-1)))
            problems.append(f"constant region changed: id {region} ({len(s)} samples of {c.tolist()}) has "
                            f"{pix[p].tolist()}: relative deviation {rel:.3g}, "
                            f"{int((dev > tol).any(-1).sum())} of {len(pix)} pixels")
    return problems, worst


def _within_own_samples(case, mode, out, fld, region):
    """Problems if a pixel of ``region`` in ``out`` leaves the range of the
    region's traced samples (per channel, with the bounds' tolerance)."""
    if case.albedo not in CONSTANT_ALBEDOS:
        # with albedo varying within an id the radiance range is no bound on the
        # pixels (irradiance and albedo are interpolated apart): as no_new_extremes
        return [], 0.0
    samples = region_samples(case, mode, out, fld).get(region)
    mine = (out.ids == region) & ~out.traced_mask
    if samples is None or not mine.any():
        return [], 0.0
    lo, hi = samples.min(0), samples.max(0)
    tol = bound_tolerance(lo, hi)
    pix = out.image[mine]
    over = np.maximum(lo - tol - pix, pix - hi - tol)
    if (over > 0).any() or not np.isfinite(pix).all():
        span = np.where(hi > lo, hi - lo, np.maximum(np.abs(hi), 1e-300))
        rel = float(np.nanmax(np.where(np.isfinite(over), over, np.inf) / span))
        return [f"leak: into id {region} (traced pixels differ), "
                f"{int((over > 0).any(-1).sum())} of {int(mine.sum())} pixels out of its "
                f"samples' range, by up to {rel:.3g} x that range"], rel
    return [], 0.0


@property_test("no_leak", cases())
def test_no_value_crosses_regions(case, mode, data):
    """Changing the values of every other id leaves an id's pixels unchanged."""
    fld = case.field
    truth = fld.ids(case.params.rule_for(mode))
    present = np.unique(truth[case.pattern.mask])
    region = int(present[data.draw(st.integers(0, len(present) - 1), label="region index")])
    rng = np.random.default_rng(data.draw(st.integers(0, 2 ** 16), label="perturbation seed"))
    scale = 10.0 ** case.exponent
    other = fld.radiance * rng.uniform(0, 5) + scale * rng.uniform(0, 2, fld.radiance.shape)
    radiance = np.where((truth == region)[..., None], fld.radiance, other)
    if case.precision == "f32":
        radiance = radiance.astype(np.float32).astype(np.float64)
    base = case.run(mode)
    changed = case.run(mode, fld.with_radiance(radiance))
    if not np.array_equal(base.traced_mask, changed.traced_mask):
        # refine traces the cells whose values the grid cannot follow, so what it
        # traces (and the ids it learns there) depends on every id's values; then
        # the region's pixels must still come from its own samples alone: within
        # their range, which the other ids' new values are not confined to
        return _within_own_samples(case, mode, changed, fld.with_radiance(radiance), region)
    if not np.array_equal(base.ids, changed.ids):
        return ["ids changed with the values of other ids"], 1.0
    mine = (base.ids == region) & ~base.traced_mask  # traced pixels keep their own values
    for out in (base, changed):  # pixels that show two surfaces take light from both
        if out.mixed is not None:  # (tests/recon/test_mixed.py bounds them)
            mine &= ~out.mixed
    s = fld.radiance[base.traced_mask & (truth == region)]
    lo, hi = s.min(0), s.max(0)
    tol = bound_tolerance(lo, hi)
    diff = np.abs(changed.image[mine] - base.image[mine])
    if (diff > tol).any() or not np.isfinite(diff).all():
        span = np.where(hi > lo, hi - lo, np.maximum(np.abs(hi), 1e-300))
        rel = float(np.nanmax(np.where(np.isfinite(diff), diff, np.inf) / span))
        return [f"leak: into id {region}, {int((diff > tol).any(-1).sum())} of {int(mine.sum())} "
                f"pixels change, by up to {rel:.3g} x the id's range"], rel
    return [], 0.0


@property_test("degenerate", degenerate_cases())
def test_degenerate_inputs(case, mode, data):
    """1 x N to 3 x N images, one sample, fraction 1 or 1e-300, an id per grid
    cell or on one or two samples, lines, diagonals, albedo 0: the mode runs,
    traced pixels are exact, the output is finite and (albedo constant per id)
    within the range of all samples."""
    out = case.run(mode)
    problems = []
    if out.image.shape != (case.height, case.width, 3):
        problems.append(f"image shape {out.image.shape}")
        return problems, 1.0
    if not np.isfinite(out.image).all():
        problems.append("non-finite output")
    mask = out.traced_mask
    if not np.array_equal(out.image[mask], case.field.radiance[mask]):
        problems.append("traced pixels differ")
    measure = 0.0
    if case.albedo in CONSTANT_ALBEDOS:
        s = case.field.radiance[mask]
        lo, hi = s.min(0), s.max(0)
        over = np.maximum(out.image - hi - bound_tolerance(lo, hi),
                          lo - bound_tolerance(lo, hi) - out.image)
        if (over > 0).any():
            measure = float(np.nanmax(over / np.where(hi > lo, hi - lo, np.maximum(hi, 1e-300))))
            problems.append(f"out of the samples' range: by {measure:.3g} x the range")
    return problems, measure


# --------------------------------------------------------------------------- earlier reports

def _trace(n, radiance, albedo, shapes):
    return SparseTrace(np.asarray(radiance, float), np.asarray(albedo, float),
                       np.asarray(shapes, np.int64), np.zeros(n, np.uint32), 0, 1, 0.0)


def test_known_paper_coarse_grid_crash():
    """Reported: paper crashed in smooth_ids on a grid much coarser than the
    quadtree cells (8 x 2 image, fraction 0.3: a 2 x 2 grid)."""
    p = grid_pattern(8, 2, 0.3)
    out = reconstruct(p, _trace(4, np.ones((4, 3)), np.ones((4, 3)), [1, 2, 2, 2]),
                      MRTParams(sample_fraction=0.3), "paper")
    assert np.isfinite(out.image).all()
    assert np.allclose(out.image, 1.0)


@pytest.mark.parametrize("mode", MODES)
def test_known_overflow_when_divided_by_albedo(mode):
    """Reported: radiance 1e38 with albedo 0.1 (finite) gave Inf/NaN: radiance /
    albedo overflows float32."""
    h = w = 8
    rng = np.random.default_rng(1)
    shapes = np.ones((h, w), np.int64)
    albedo = np.where(rng.random((h, w, 1)) < 0.5, 0.1, 0.2) * np.ones(3)  # varies within the id
    case = Case(h, w, 0.3)
    from .stress_support import Field
    fld = Field(shapes, np.full((h, w, 3), 1e38), albedo, np.zeros((h, w), np.uint32), 0)
    try:
        out = case.run(mode, fld)
    except MRTError:
        return
    assert np.isfinite(out.image).all(), f"{int((~np.isfinite(out.image)).any(-1).sum())} non-finite pixels"


@pytest.mark.parametrize("degree", [-1, 0, 1])
def test_known_paper_rbf_near_float32_max(degree):
    """Reported: the RBF raised a raw ValueError for values near float32's max.
    Only from 128 samples per id (rbf_solve.MIN_SIZE) is the float32 Cholesky
    used, so the image has 144 samples of one id."""
    p = grid_pattern(12, 12, 1.0)
    radiance = np.random.default_rng(0).uniform(0.5, 1.0, (p.count, 3)) * 3.0e38
    try:
        out = reconstruct(p, _trace(p.count, radiance, np.ones((p.count, 3)), np.ones(p.count)),
                          MRTParams(sample_fraction=1.0, rbf_degree=degree), "paper")
    except MRTError:
        return
    assert np.isfinite(out.image).all()


def _stripes_field():
    """7 x 25 vertical stripes: shape 1 on columns 0-5 and 19-23, 2 on 6-18, 3 on 24."""
    from .stress_support import Field
    ids = np.tile(np.array([1] * 6 + [2] * 13 + [1] * 5 + [3]), (7, 1)).astype(np.int64)
    radiance = np.repeat(np.array([0.0, 1.0, 100.0, 50.0])[ids][..., None], 3, 2)
    return Field(ids, radiance, np.ones((7, 25, 3)), np.zeros((7, 25), np.uint32), 0)


@pytest.mark.parametrize("mode", MODES)
def test_known_leak_into_a_region_found_by_refinement(mode):
    """Reported: values leak between ids in fast/refine.  Refinement finds the
    second stripe of shape 1 (grid: rows 0, 6; columns 0, 6, 12, 18, 24), but
    no grid sample of shape 1 is in its pixels' 4 x 4 blocks, so they take the
    nearest grid sample of any id (100 or 50) instead of 1."""
    fld = _stripes_field()
    case = Case(7, 25, 10 / 175)
    out = case.run(mode, fld)
    one = out.ids == out.ids[0, 0]
    wrong = one & (np.abs(out.image[..., 0] - 1.0) > 1e-5)
    assert not wrong.any(), (f"{int(wrong.sum())} pixels of shape 1 (all samples 1.0) hold "
                             f"{np.unique(out.image[wrong, 0]).tolist()}")


@pytest.mark.parametrize("mode", ["paper", "fast"])
def test_known_leak_after_smoothing(mode):
    """The id smoothing grows shape 1 (one sample, 1.25) two grid rows down a
    4 x 2 image traced in column 0; pixel (2, 1) then has no sample of its id
    in its 4 x 4 block and takes the background's 0.13."""
    p = grid_pattern(2, 4, 0.5)
    radiance = np.array([[1.25] * 3, [0.13] * 3, [0.13] * 3, [0.13] * 3])
    out = reconstruct(p, _trace(4, radiance, np.ones((4, 3)), [1, 0, 0, 0]),
                      MRTParams(sample_fraction=0.5), mode)
    one = (out.ids == out.ids[0, 0]) & ~out.traced_mask
    assert np.allclose(out.image[one], 1.25, rtol=1e-5), out.image[..., 0]
