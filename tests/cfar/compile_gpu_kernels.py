"""Compile torchsar's Triton kernels to machine code for a Hopper GPU (sm_90: H100, H200)
without one: Triton's own compiler and the ptxas it ships, no driver. Run as a script by
``test_gpu_kernels.py`` (its own process: the test process runs the kernels in Triton's
interpreter, which must not be on here); prints one line per kernel and variant. Importing
this file does nothing (the test run's doctest collection imports it)."""

from __future__ import annotations

import os

RING_RATIO = {
    "x_ptr": "*fp32",
    "scale_ptr": "*fp64",
    "thr_ptr": "*fp32",
    "out_ptr": "*fp32",
    "mask_ptr": "*i8",
    "h": "i32",
    "w": "i32",
    "G": "i32",
    "R": "i32",
    "BH": "constexpr",
    "BW": "constexpr",
}
REGION_SUMS = {
    "x_ptr": "*fp32",
    "shift_ptr": "*fp64",
    "rect_ptr": "*i32",
    "start_ptr": "*i32",
    "s1_ptr": "*fp64",
    "s2_ptr": "*fp64",
    "planes": "i32",
    "h": "i32",
    "w": "i32",
    "r0": "i32",
    "rr": "i32",
    "regions": "i32",
    "pad": "i32",
    "MOMENTS": "constexpr",
    "BH": "constexpr",
    "BW": "constexpr",
}
OS = {
    "x_ptr": "*fp32",
    "dr_ptr": "*i32",
    "dc_ptr": "*i32",
    "ranks_ptr": "*i32",
    "scale_ptr": "*fp64",
    "thr_ptr": "*fp32",
    "out_ptr": "*fp32",
    "mask_ptr": "*i8",
    "h": "i32",
    "w": "i32",
    "total": "i64",
    "N": "i32",
    "NP": "constexpr",
    "BLOCK": "constexpr",
    "STAT": "constexpr",
}


def main() -> None:
    os.environ.pop("TRITON_INTERPRET", None)
    import triton  # before the kernels: they then stay compiled
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource

    from torchsar import _gpu_kernels as gk

    target = GPUTarget("cuda", 90, 32)
    bh, bw = gk._CA_TILE
    variants = [("ring_ratio", gk._ring_ratio_kernel, RING_RATIO, {"BH": bh, "BW": bw})]
    for moments in (1, 2):
        consts = {"MOMENTS": moments, "BH": bh, "BW": bw}
        variants.append(
            (f"region_sums MOMENTS={moments}", gk._region_sums_kernel, REGION_SUMS, consts)
        )
    for npad in (64, 256):
        for stat in (True, False):
            block = max(1, gk._OS_CELLS // npad)
            consts = {"NP": npad, "BLOCK": block, "STAT": stat}
            variants.append((f"os NP={npad} STAT={stat}", gk._os_kernel, OS, consts))
    for name, fn, signature, constexprs in variants:
        kernel = triton.compile(ASTSource(fn, signature, constexprs), target=target)
        print(name, "ok", len(kernel.asm["cubin"]), "bytes of sm_90 code")


if __name__ == "__main__":
    main()
