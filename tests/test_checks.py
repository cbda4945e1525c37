from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given
from hypothesis import strategies as st

from torchsar import _checks as C
from torchsar import errors as E


class TestCheckImage:
    def test_accepts_valid(self):
        x = torch.rand(2, 1, 4, 4)
        assert C.check_image(x) is x

    def test_empty_batch_is_valid(self):
        C.check_image(torch.zeros(0, 1, 4, 4))

    @pytest.mark.parametrize("bad", [[1.0], None, 3.0])
    def test_not_a_tensor(self, bad):
        with pytest.raises(E.InputTypeError, match="x must be a torch.Tensor"):
            C.check_image(bad)

    def test_wrong_ndim_names_axes(self):
        with pytest.raises(E.ShapeError, match=r"img must have shape \(B, C, H, W\).*\(4, 4\)"):
            C.check_image(torch.rand(4, 4), "img")

    def test_complex_where_real(self):
        with pytest.raises(E.InputTypeError, match="must be real"):
            C.check_image(torch.zeros(1, 1, 2, 2, dtype=torch.complex64))

    def test_real_where_complex(self):
        with pytest.raises(E.InputTypeError, match="must be complex"):
            C.check_complex(torch.zeros(1, 2, 2))

    def test_integer_dtype(self):
        with pytest.raises(E.InputTypeError, match="floating dtype"):
            C.check_image(torch.zeros(1, 1, 2, 2, dtype=torch.int64))

    @pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf")])
    def test_non_finite(self, value):
        x = torch.ones(1, 1, 3, 3)
        x[0, 0, 1, 1] = value
        with pytest.raises(E.InputValueError, match="must be finite"):
            C.check_image(x)

    def test_the_fix_the_message_gives_works(self):
        """A NaN no-data area: the message's advice (replace the values, pass the mask of
        finite cells) runs, and the no-data pixels are never detected."""
        import torchsar as ts

        x = torch.ones(1, 1, 24, 24)
        x[0, 0, 5:9, 5:9] = float("nan")
        x[0, 0, 15, 15] = 1e3
        with pytest.raises(E.InputValueError, match=r"x\.nan_to_num.*x\.isfinite\(\)") as err:
            ts.cfar.ca(x)
        assert "`valid` mask" in str(err.value)
        det = ts.cfar.ca(x.nan_to_num(0.0, 0.0, 0.0), valid=x.isfinite())
        assert det.mask[0, 0, 15, 15] and not det.mask[0, 0, 5:9, 5:9].any()

    @pytest.mark.parametrize("dtype", [torch.float16, torch.bfloat16, torch.float32, torch.float64])
    @pytest.mark.parametrize("value", [float("nan"), float("inf"), -float("inf"), -1.0, -0.0, 0.0])
    def test_one_bad_value_among_many_in_any_float_dtype(self, dtype, value):
        """Non-finite first (a NaN beside negatives is a NaN error), then negative; ``-0.0``
        is zero."""
        x = torch.rand(2, 1, 33, 35, generator=torch.Generator().manual_seed(0)).to(dtype)
        x[1, 0, 20, 7] = value
        if math.isfinite(value) and value >= 0:
            assert C.check_image(x) is x
            return
        x[0, 0, 3, 3] = -2.0
        what = "must be finite" if not math.isfinite(value) else "non-negative"
        with pytest.raises(E.InputValueError, match=what):
            C.check_image(x)
        if math.isfinite(value):
            assert C.check_image(x, nonnegative=False) is x

    def test_negative(self):
        x = torch.ones(1, 1, 3, 3)
        x[0, 0, 0, 0] = -0.5
        with pytest.raises(E.InputValueError, match="non-negative.*-0.5"):
            C.check_image(x)

    def test_grad_refused_only_where_not_differentiable(self):
        x = torch.rand(1, 1, 3, 3, requires_grad=True)
        assert C.check_image(x) is x
        with pytest.raises(E.InputTypeError, match=r"x requires grad; os is not .* x.detach\(\)"):
            C.check_image(x, not_differentiable="os")
        assert C.check_image(x.detach(), not_differentiable="os") is not None

    def test_errors_are_builtin_subclasses(self):
        assert issubclass(E.InputTypeError, TypeError)
        assert issubclass(E.InputValueError, ValueError)
        assert issubclass(E.WindowSizeError, ValueError)


class TestOptions:
    def test_window_fits(self):
        with pytest.raises(E.WindowSizeError, match="13x13 pixels is larger than the image"):
            C.check_window_fits(torch.zeros(1, 1, 10, 20), 13, "guard + train")

    @pytest.mark.parametrize("v", [0, 2, 1.0, True])
    def test_odd(self, v):
        with pytest.raises(E.OptionError, match="window"):
            C.check_odd(v, "window", minimum=3)

    @pytest.mark.parametrize("v", [0, 1, -0.1, 1.5, "a"])
    def test_probability(self, v):
        with pytest.raises(E.OptionError, match="pfa must be a probability"):
            C.check_probability(v)

    def test_choice_lists_allowed(self):
        with pytest.raises(E.OptionError, match="'a', 'b'.*'c'"):
            C.check_choice("c", "mode", ["a", "b"])

    def test_positive(self):
        assert C.check_positive(2, "looks") == 2.0
        with pytest.raises(E.OptionError, match="looks"):
            C.check_positive(0, "looks")
        with pytest.raises(E.OptionError, match="looks"):
            C.check_positive(float("nan"), "looks")

    def test_float_dtype_policy(self):
        assert C.float_dtype(torch.float64) is torch.float64
        assert C.float_dtype(torch.float16) is torch.float32
        assert C.float_dtype(torch.complex128) is torch.float64


_SPECIAL = st.sampled_from([0.0, 1.0, -2.5, 3e38, -3e38, 1e-45, math.inf, -math.inf, math.nan])


@given(st.lists(_SPECIAL, min_size=1, max_size=12), st.sampled_from([torch.float32, torch.float64]))
def test_all_finite_and_has_nan_equal_elementwise_tests(values, dtype):
    """The summation shortcuts agree with the elementwise tests, overflowing sums and
    ``inf - inf`` included."""
    x = torch.tensor(values, dtype=dtype)
    assert C.all_finite(x) == bool(torch.isfinite(x).all())
    assert C.has_nan(x) == bool(torch.isnan(x).any())


def test_broadcasts_agrees_with_torch_on_random_shapes():
    import random

    import torch

    from torchsar._checks import broadcasts

    rng = random.Random(0)
    for _ in range(500):
        a = tuple(rng.choice([0, 1, 2, 3]) for _ in range(rng.randint(0, 4)))
        b = tuple(rng.choice([0, 1, 2, 3]) for _ in range(rng.randint(0, 4)))
        try:
            torch.broadcast_shapes(a, b)
            want = True
        except RuntimeError:
            want = False
        assert broadcasts(a, b) is want, (a, b)
