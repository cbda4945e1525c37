from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st
from scipy.ndimage import fourier_shift
from skimage.registration import phase_cross_correlation

from torchsar.errors import InputTypeError, InputValueError, OptionError, ShapeError
from torchsar.motion import estimate_shift


def _shifted(seed: int, shape=(40, 48), d=(0.0, 0.0), smooth=True):
    rng = np.random.default_rng(seed)
    a = rng.random(shape)
    if smooth:
        a = np.fft.ifftn(np.fft.fftn(a) * _lowpass(shape)).real
    b = np.fft.ifftn(fourier_shift(np.fft.fftn(a), d)).real
    return a, b


def _lowpass(shape):
    fy, fx = np.meshgrid(*(np.fft.fftfreq(n) for n in shape), indexing="ij")
    return np.exp(-(fy**2 + fx**2) / (2 * 0.08**2))


class TestEstimateShift:
    @given(
        dy=st.floats(-6, 6),
        dx=st.floats(-6, 6),
        seed=st.integers(0, 1000),
        norm=st.sampled_from([None, "phase"]),
    )
    def test_agrees_with_skimage(self, dy, dx, seed, norm):
        a, b = _shifted(seed, d=(dy, dx), smooth=False)
        ref = phase_cross_correlation(a, b, upsample_factor=20, normalization=norm)[0]
        got = estimate_shift(torch.tensor(a), torch.tensor(b), upsample=20, normalization=norm)
        np.testing.assert_allclose(got.numpy(), ref, atol=1e-9)

    @pytest.mark.parametrize("d", [(0.3, -0.45), (2.25, 1.1), (-3.7, 0.05)])
    def test_recovers_known_subpixel_shift(self, d):
        a, b = _shifted(3, d=d)
        got = estimate_shift(torch.tensor(a), torch.tensor(b), upsample=50)
        np.testing.assert_allclose(got.numpy(), -np.asarray(d), atol=0.05)

    def test_batched_equals_loop_and_batch_sizes(self):
        pairs = [_shifted(s, d=(s * 0.7 - 2, 1.3 - s * 0.4)) for s in range(6)]
        a = torch.tensor(np.stack([p[0] for p in pairs])).reshape(2, 3, 40, 48)
        b = torch.tensor(np.stack([p[1] for p in pairs])).reshape(2, 3, 40, 48)
        out = estimate_shift(a, b)
        assert out.shape == (2, 3, 2)
        for i in range(6):
            one = estimate_shift(a.reshape(6, 40, 48)[i], b.reshape(6, 40, 48)[i])
            torch.testing.assert_close(out.reshape(6, 2)[i], one)
        assert estimate_shift(a[:0], b[:0]).shape == (0, 3, 2)

    def test_integer_only_and_complex_input(self):
        a, b = _shifted(5, d=(3.0, -2.0))
        got = estimate_shift(torch.tensor(a), torch.tensor(b), upsample=1)
        assert got.tolist() == [-3.0, 2.0]
        ca = torch.tensor(a) * (1 + 1j)
        cb = torch.tensor(b) * (1 + 1j)
        assert estimate_shift(ca, cb, upsample=1).tolist() == [-3.0, 2.0]

    def test_dtype_and_non_contiguous(self):
        a, b = _shifted(6, d=(1.5, 0.5))
        ta, tb = torch.tensor(a).float(), torch.tensor(b).float()
        assert estimate_shift(ta, tb).dtype == torch.float32
        wide_a = torch.stack([ta, ta], -1)[..., 0]
        assert not wide_a.is_contiguous()
        torch.testing.assert_close(estimate_shift(wide_a, tb), estimate_shift(ta, tb))

    def test_errors(self):
        x = torch.zeros(8, 8)
        with pytest.raises(ShapeError, match="same shape"):
            estimate_shift(x, torch.zeros(8, 9))
        with pytest.raises(ShapeError, match=r"\(\.\.\., H, W\)"):
            estimate_shift(torch.zeros(8), torch.zeros(8))
        with pytest.raises(InputTypeError, match="ref"):
            estimate_shift(np.zeros((8, 8)), x)
        with pytest.raises(InputTypeError, match="floating"):
            estimate_shift(x.long(), x.long())
        with pytest.raises(OptionError, match="upsample"):
            estimate_shift(x, x, upsample=0)
        with pytest.raises(OptionError, match="normalization"):
            estimate_shift(x, x, normalization="cross")

    @pytest.mark.parametrize("bad", [float("nan"), float("inf")])
    def test_non_finite_input_is_refused(self, bad):
        x = torch.rand(2, 8, 8, generator=torch.Generator().manual_seed(0))
        y = x.clone()
        y[1, 3, 4] = bad
        with pytest.raises(InputValueError, match="mov must be finite"):
            estimate_shift(x, y)
        with pytest.raises(InputValueError, match="ref must be finite"):
            estimate_shift(y.to(torch.complex64), x.to(torch.complex64))
