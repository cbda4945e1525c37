from __future__ import annotations

import math

import pytest
import torch

from torchsar.cfar import detection_from
from torchsar.errors import InputTypeError
from torchsar.motion import (
    associate,
    detect_peaks,
    measure_displacements,
    subpatch_centers,
)


def _blobs(params, centers, positions, sigma_px=1.6):
    """Complex images (1, P, H, W) with Gaussian blobs at ``positions (N, P, 2)`` (m, relative)."""
    h, w = params.image_size
    dy, dx = params.pixel_spacing
    yy, xx = torch.meshgrid(
        torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij"
    )
    imgs = torch.zeros(1, centers.shape[0], h, w, dtype=torch.complex128)
    for p in range(centers.shape[0]):
        for n in range(positions.shape[0]):
            r = positions[n, p, 0] / dy + h // 2
            c = positions[n, p, 1] / dx + w // 2
            imgs[0, p] += torch.exp(-((yy - r) ** 2 + (xx - c) ** 2) / (2 * sigma_px**2)) * (
                1 + 0.5j
            )
    return imgs


def _threshold(x):
    return detection_from(x, 0.1 * float(x.max()))


class TestAssociate:
    def test_hand_case_gate_and_periodic(self):
        ref = torch.tensor([[0.0, 0.0], [10.0, 0.0], [40.0, 40.0]])
        cand = torch.tensor([[11.0, 1.0], [1.0, -1.0], [-49.0, 40.0]])
        period = torch.tensor([90.0, 1e9])
        got = associate(ref, cand, torch.zeros(2), period, 3.0)
        assert got.tolist() == [1, 0, 2]  # 40 and -49 are 1 m apart modulo 90
        assert associate(ref, cand[:0], torch.zeros(2), period, 3.0).tolist() == [-1, -1, -1]
        shifted = associate(
            ref, cand + torch.tensor([5.0, 0.0]), torch.tensor([5.0, 0.0]), period, 3.0
        )
        assert shifted.tolist() == [1, 0, 2]


class TestMeasureDisplacements:
    def test_synthetic_blobs_recover_excess_displacement(self, small):
        c = subpatch_centers(small)
        truth = torch.tensor([[10.0, -20.0], [-25.0, 5.0], [30.0, 15.0]], dtype=torch.float64)
        pos = truth[:, None, :] - c[None]  # stationary: s - c_p
        extra = torch.tensor(
            [[0.0, 0.0], [0.31, -0.12], [-0.22, 0.41], [0.09, 0.27]], dtype=torch.float64
        )
        pos[2] += extra  # target 2 moves differently in each image
        imgs = _blobs(small, c, pos)
        tr = measure_displacements(imgs, small, c, detector=_threshold, radius=4, chip=16)
        assert tr.valid.all() and tr.excess.shape == (1, 3, 4, 2)
        mover = int(torch.argmin((tr.position[0, :, 0] - pos[2, 0]).norm(dim=-1)))
        for n in range(3):
            want = extra - extra[0] if n == mover else torch.zeros(4, 2, dtype=torch.float64)
            torch.testing.assert_close(tr.excess[0, n], want, atol=0.03, rtol=0)
        assert (tr.pixel[0, :, :, 0] >= 0).all()

    def test_batch_padding_and_empty(self, tiny):
        c = subpatch_centers(tiny)
        imgs = torch.zeros(2, 4, 64, 64, dtype=torch.complex64)
        imgs[0, :, 32, 32] = 1.0
        tr = measure_displacements(
            imgs, tiny, c, detector=lambda x: detection_from(x, 0.5), radius=2, chip=8, gate=40.0
        )
        assert tr.valid.shape[:2] == (2, 1)
        assert not tr.valid[1].any() and math.isnan(float(tr.excess[1, 0, 0, 0]))
        empty = measure_displacements(imgs[:0], tiny, c, chip=8)
        assert empty.excess.shape == (0, 0, 4, 2)

    def test_errors(self, tiny):
        with pytest.raises(InputTypeError, match="complex"):
            measure_displacements(torch.zeros(1, 4, 8, 8), tiny, subpatch_centers(tiny))


class TestDetectPeaks:
    def test_one_peak_per_blob_and_circular_border(self):
        x = torch.zeros(1, 1, 20, 20)
        x[0, 0, 0, 5], x[0, 0, 19, 5], x[0, 0, 10, 10], x[0, 0, 10, 12] = 5.0, 4.0, 3.0, 2.0
        det = detect_peaks(x, detector=lambda v: detection_from(v, 1.0), radius=2)
        assert det.nonzero().tolist() == [[0, 0, 0, 5], [0, 0, 10, 10]]
        det0 = detect_peaks(x, detector=lambda v: detection_from(v, 1.0), radius=0)
        assert int(det0.sum()) == 4
