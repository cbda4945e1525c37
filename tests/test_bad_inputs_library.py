"""Bad inputs to the library's public functions: each is refused with a typed error naming
the argument, or handled correctly, never a silent wrong result, a crash deep inside or a
hang. The table holds the refusals; the property tests below it check the inputs that are
now handled (data of any magnitude, complex32, a scalar pixel area)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy import ndimage
from skimage.morphology import disk

from torchsar.errors import (
    InputTypeError,
    InputValueError,
    OptionError,
    ShapeError,
    WindowSizeError,
)
from torchsar.imaging import (
    apply_phase_error,
    contrast,
    default_lam,
    entropy,
    fft2c,
    ifft2c,
    lp_image,
    magnitude_correlation,
    min_entropy_autofocus,
    pga,
    pulse_autofocus,
    pulse_min_entropy,
    sharpness,
    sparse_autofocus,
    target_to_background,
)
from torchsar.metrics.matching import ground_truth
from torchsar.objects import ObjectRules, discriminate
from torchsar.region import region_cfar
from torchsar.speckle import FILTERS

NAN = float("nan")


def _ids(values: np.ndarray) -> np.ndarray:
    """One 6 x 6 plane with a 2 x 2 instance holding ``values`` (broadcast)."""
    inst = np.zeros((1, 6, 6), dtype=np.asarray(values).dtype)
    inst[0, 1:3, 1:3] = values
    return inst


def _stat(planes: tuple[int, int] = (1, 1), size: int = 8) -> torch.Tensor:
    s = torch.zeros(*planes, size, size)
    s[..., 1:3, 1:3] = 5.0
    return s


def _phase_history(batch: int = 1, size: int = 16) -> torch.Tensor:
    """Two point scatterers under a quadratic phase error, light seeded noise."""
    f = torch.zeros(batch, size, size, dtype=torch.complex64)
    f[:, 5, 9] = 1.0
    f[:, 2, 3] = 0.5j
    phi = 2.0 * torch.linspace(-1, 1, size)[None].expand(batch, size) ** 2
    noise = torch.randn(
        batch, size, size, dtype=torch.complex64, generator=torch.Generator().manual_seed(3)
    )
    return apply_phase_error(fft2c(f), phi) + 0.01 * noise


def _pulses(batch: int = 1) -> torch.Tensor:
    """Per-pulse images ``(B, M, H, W)`` of one point with per-pulse phases."""
    b = torch.zeros(batch, 6, 5, 5, dtype=torch.complex64)
    b[:, :, 2, 3] = torch.polar(torch.ones(6), torch.tensor([0.0, 1.0, 2.0, 0.5, -1.0, 0.3]))
    b[:, :, 1, 1] = 0.2
    return b


def _region_image() -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    x = torch.ones(1, 1, 40, 40)
    x[..., 10:18, 10:18] = 10.0
    x[..., 26:32, 20:34] = 6.0
    return x * (1 + 0.3 * torch.rand(x.shape, generator=g))


M2 = ObjectRules(units="m2")

# (id, call, expected exception, regex naming the argument)
CASES = [
    (
        "ground_truth-fractional-ids",
        lambda: ground_truth(_ids(np.array(1.5))),
        InputTypeError,
        "instances",
    ),
    (
        "ground_truth-nan-ids",
        lambda: ground_truth(_ids(np.array(NAN))),
        InputTypeError,
        "instances",
    ),
    (
        "ground_truth-negative-ids",
        lambda: ground_truth(_ids(np.array(-1))),
        InputValueError,
        "instances",
    ),
    ("ground_truth-2d-ids", lambda: ground_truth(_ids(np.array(1))[0]), ShapeError, "instances"),
    (
        "ground_truth-ignore-shape",
        lambda: ground_truth(_ids(np.array(1)), np.zeros((1, 3, 3))),
        ShapeError,
        "ignore",
    ),
    (
        "discriminate-nan-threshold",
        lambda: discriminate(_stat(), NAN),
        InputValueError,
        "threshold",
    ),
    (
        "discriminate-nan-in-threshold-map",
        lambda: discriminate(_stat(), torch.full((1, 1, 8, 8), NAN)),
        InputValueError,
        "threshold",
    ),
    (
        "discriminate-threshold-shape",
        lambda: discriminate(_stat(), torch.ones(3)),
        ShapeError,
        "threshold",
    ),
    (
        "discriminate-complex-threshold",
        lambda: discriminate(_stat(), torch.tensor(2.0 + 1j)),
        InputTypeError,
        "threshold",
    ),
    (
        "discriminate-negative-pixel-area",
        lambda: discriminate(_stat(), 1.0, rules=M2, pixel_area=-1.0),
        InputValueError,
        "pixel_area",
    ),
    (
        "discriminate-nan-pixel-area",
        lambda: discriminate(_stat(), 1.0, rules=M2, pixel_area=NAN),
        InputValueError,
        "pixel_area",
    ),
    (
        "discriminate-pixel-area-count",
        lambda: discriminate(_stat((1, 2)), 1.0, rules=M2, pixel_area=np.ones(3)),
        ShapeError,
        "pixel_area",
    ),
    (
        "discriminate-closing-beyond-image",
        lambda: discriminate(_stat(size=4), 1.0, rules=ObjectRules(closing=5)),
        WindowSizeError,
        "closing",
    ),
    (
        "discriminate-rules-not-ObjectRules",
        lambda: discriminate(_stat(), 1.0, rules={"closing": 1}),
        OptionError,
        "rules",
    ),
    (
        "sparse_autofocus-nan-lam",
        lambda: sparse_autofocus(_phase_history(), lam=torch.tensor([NAN]), max_iter=2),
        OptionError,
        "lam",
    ),
    (
        "lp_image-inf-lam",
        lambda: lp_image(_phase_history(), lam=torch.tensor([float("inf")])),
        OptionError,
        "lam",
    ),
    (
        "default_lam-nan-kappa",
        lambda: default_lam(_phase_history(), kappa=NAN),
        OptionError,
        "kappa",
    ),
    (
        "pga-several-channels",
        lambda: pga(ifft2c(_phase_history(2)).reshape(1, 2, 16, 16)),
        ShapeError,
        "image",
    ),
    (
        "pga-nan-window_db",
        lambda: pga(ifft2c(_phase_history()).unsqueeze(1), window_db=NAN),
        OptionError,
        "window_db",
    ),
    ("pulse_autofocus-p-above-2", lambda: pulse_autofocus(_pulses(), p=3.0), OptionError, r"\bp\b"),
    (
        "pulse_autofocus-nan-kappa",
        lambda: pulse_autofocus(_pulses(), kappa=NAN),
        OptionError,
        "kappa",
    ),
    (
        "pulse_autofocus-negative-tol",
        lambda: pulse_autofocus(_pulses(), tol=-1.0),
        OptionError,
        "tol",
    ),
    (
        "pulse_autofocus-zero-inner",
        lambda: pulse_autofocus(_pulses(), inner=0),
        OptionError,
        "inner",
    ),
    (
        "apply_phase_error-nan-phi",
        lambda: apply_phase_error(_phase_history(), torch.full((1, 16), NAN)),
        InputValueError,
        "phi",
    ),
    (
        "region_cfar-despeckle-returns-inf",
        lambda: region_cfar(_region_image(), despeckle=lambda t: t * float("inf")),
        InputValueError,
        "despeckle",
    ),
]


@pytest.mark.parametrize(
    ("call", "error", "name"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_bad_input_is_refused_by_name(call, error, name):
    with pytest.raises(error, match=name):
        call()


# -- inputs that are now handled -------------------------------------------------------------


def test_whole_number_float_ids_equal_integer_ids():
    inst = np.zeros((2, 6, 6), dtype=np.int64)
    inst[0, 1:3, 1:3], inst[1, 4:6, 0:2], inst[1, 0, 5] = 1, 3, 1
    a, b = ground_truth(inst), ground_truth(inst.astype(np.float32))
    assert len(a) == len(b) == 3
    assert np.array_equal(a.ids, b.ids) and np.array_equal(a.box, b.box)


def test_scalar_pixel_area_equals_per_plane_calls():
    g = torch.Generator().manual_seed(1)
    stat = torch.rand(2, 3, 12, 12, generator=g) * 3
    rules = ObjectRules(units="m2", min_area=6.0, max_area=40.0)
    whole = discriminate(stat, 2.0, rules=rules, pixel_area=2.0)
    each = np.full(6, 2.0)
    same = discriminate(stat, 2.0, rules=rules, pixel_area=each)
    assert np.array_equal(whole.labels, same.labels)
    parts = [
        discriminate(stat[i : i + 1, j : j + 1], 2.0, rules=rules, pixel_area=2.0)
        for i in range(2)
        for j in range(3)
    ]
    assert whole.area.tolist() == np.concatenate([p.area for p in parts]).tolist()
    assert whole.score.tolist() == np.concatenate([p.score for p in parts]).tolist()
    assert whole.plane.tolist() == [k for k, p in enumerate(parts) for _ in range(len(p))]


def _reference_closing(mask: np.ndarray, radius: int) -> np.ndarray:
    """Closing by a disk with scipy (outside unset for the dilation, set for the erosion)."""
    fp = disk(radius).astype(bool)
    grown = ndimage.binary_dilation(np.pad(mask, radius), fp)
    return ndimage.binary_erosion(grown, fp, border_value=1)[radius:-radius, radius:-radius] | mask


def test_closing_radius_beyond_the_image_is_not_a_clipped_radius():
    """Why a closing larger than the image is refused rather than clipped: the closing keeps
    changing with the radius beyond the image size (it tends to the mask's hull)."""
    rng = np.random.default_rng(0)
    found = False
    for _ in range(50):
        mask = rng.random((5, 6)) < 0.2
        if not np.array_equal(_reference_closing(mask, 6), _reference_closing(mask, 12)):
            found = True
            break
    assert found
    stat = torch.as_tensor(mask[None, None] * 5.0)
    obj = discriminate(stat, 1.0, rules=ObjectRules(closing=6))  # the largest radius accepted
    assert np.array_equal(obj.labels[0] > 0, _reference_closing(mask, 6))


SCALES = [1e20, 1e-20]


def _close(a: torch.Tensor, b: torch.Tensor, rtol: float) -> None:
    scale = a.abs().max()
    assert torch.isfinite(b).all()
    assert float((a - b).abs().max()) <= rtol * float(scale)


@pytest.mark.parametrize("s", SCALES)
@pytest.mark.parametrize(
    ("method", "data", "rtol"),
    [
        (lambda g: sparse_autofocus(g, max_iter=15), _phase_history, 1e-4),
        (lambda g: sparse_autofocus(g, max_iter=15, p=0.5), _phase_history, 1e-4),
        (lambda g: min_entropy_autofocus(g, max_iter=8), _phase_history, 1e-3),
        (lambda g: pga(ifft2c(g).unsqueeze(1)), _phase_history, 1e-4),
        (pulse_autofocus, _pulses, 1e-4),
        (lambda b: pulse_min_entropy(b, max_iter=10), _pulses, 1e-3),
    ],
    ids=["sparse", "sparse-p0.5", "min_entropy", "pga", "pulse", "pulse_min_entropy"],
)
def test_autofocus_is_scale_free(method, data, rtol, s):
    g = data(2)
    a, b = method(g), method(g * s)
    _close(a.image, b.image / s, rtol)
    _close(a.phase, b.phase, rtol * 10)


@pytest.mark.parametrize("s", SCALES)
def test_lp_image_is_scale_free(s):
    g = _phase_history(2)
    _close(lp_image(g, max_iter=15), lp_image(g * s, max_iter=15) / s, 1e-4)


def test_sparse_autofocus_cost_and_lam_scale_with_the_data():
    g = _phase_history(2)
    s = 2.0**30
    a, b = sparse_autofocus(g, max_iter=10), sparse_autofocus(g * s, max_iter=10)
    torch.testing.assert_close(b.lam, a.lam * s)  # p = 1: lam scales as the data
    torch.testing.assert_close(b.cost, a.cost * s * s)


@pytest.mark.filterwarnings("ignore:ComplexHalf support is experimental")
@pytest.mark.parametrize(
    "method",
    [
        lambda g: sparse_autofocus(g, max_iter=5),
        lambda g: min_entropy_autofocus(g, max_iter=5),
    ],
    ids=["sparse", "min_entropy"],
)
def test_complex32_computes_in_complex64(method):
    half = _phase_history(1).to(torch.complex32)
    out = method(half)
    ref = method(half.to(torch.complex64))
    assert out.image.dtype == torch.complex64
    assert torch.equal(out.image, ref.image) and torch.equal(out.phase, ref.phase)


def test_focus_metrics_and_correlation_are_scale_free():
    g = torch.Generator().manual_seed(2)
    x = torch.rand(2, 1, 12, 12, generator=g) + 0.1
    mask = x > 0.6
    for metric in (entropy, contrast, sharpness, lambda t: target_to_background(t, mask)):
        torch.testing.assert_close(metric(x * 3e37), metric(x))
    f = torch.randn(2, 1, 8, 8, dtype=torch.complex64, generator=g)
    torch.testing.assert_close(
        magnitude_correlation(f.roll(2, -1) * 1e20, f * 1e20),
        magnitude_correlation(f.roll(2, -1), f),
    )


@pytest.mark.parametrize("name", sorted(FILTERS))
def test_speckle_filters_exact_on_huge_amplitudes(name):
    g = torch.Generator().manual_seed(4)
    x = torch.rand(1, 2, 12, 12, generator=g) * 10 + 0.1
    s = 2.0**100  # amplitude ~1e31: its square overflows float32
    out = FILTERS[name](x * s, amplitude=True)
    assert torch.equal(out / s, FILTERS[name](x, amplitude=True))


@pytest.mark.parametrize("s", [2.0**122, 2.0**-120], ids=["huge", "tiny"])
def test_region_cfar_is_scale_free(s):
    x = _region_image()
    a, b = region_cfar(x), region_cfar(x * s)
    assert bool(a.mask.any())
    assert torch.equal(a.mask, b.mask) and torch.equal(a.labels, b.labels)
    assert torch.equal(a.statistic, b.statistic)
