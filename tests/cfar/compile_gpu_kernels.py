"""Compile torchsar's Triton kernels to machine code for a Hopper GPU (sm_90: H100, H200)
without one: Triton's own compiler and the ptxas it ships, no driver. Run as a script by
``test_gpu_kernels.py`` (its own process: the test process runs the kernels in Triton's
interpreter, which must not be on here); prints one line per kernel and variant. Importing
this file does nothing (the test run's doctest collection imports it)."""

from __future__ import annotations

import os
import re
import subprocess
import tempfile
from pathlib import Path

# the kernels' pointer arguments by name; compile-time constants aside, the others are
# 32-bit integers
POINTERS = {
    "x_ptr": "*fp32",
    "thr_ptr": "*fp32",
    "out_ptr": "*fp32",
    "mask_ptr": "*i8",
    "scale_ptr": "*fp64",
    "shift_ptr": "*fp64",
    "valid_ptr": "*i8",
    "count_ptr": "*fp64",
    "s1_ptr": "*fp64",
    "s2_ptr": "*fp64",
    "ranks_ptr": "*i32",
    "rect_ptr": "*i32",
    "start_ptr": "*i32",
    "dr_ptr": "*i32",
    "dc_ptr": "*i32",
}


def _signature(kernel) -> dict[str, str]:
    """The argument types of a Triton kernel, from its argument names."""
    return {
        p.name: "constexpr" if p.is_constexpr else POINTERS.get(p.name, "i32")
        for p in kernel.params
    }


def _ptxas() -> Path | None:
    """A ptxas that reads the PTX this Triton writes (its bundled newest one), for the
    register and spill counts."""
    import triton

    folder = Path(triton.__file__).parent / "backends" / "nvidia" / "bin"
    for name in ("ptxas-blackwell", "ptxas"):
        if (folder / name).is_file():
            return folder / name
    return None


def _resources(ptx: str) -> str:
    """``registers=R spills=S`` of the sm_90a build of ``ptx`` (empty when no ptxas can)."""
    ptxas = _ptxas()
    if ptxas is None:
        return ""
    with tempfile.TemporaryDirectory() as tmp:
        src = Path(tmp) / "kernel.ptx"
        src.write_text(ptx)
        run = subprocess.run(
            [str(ptxas), "-arch=sm_90a", "-v", str(src), "-o", str(Path(tmp) / "kernel.cubin")],
            capture_output=True,
            text=True,
        )
    regs = re.search(r"Used (\d+) registers", run.stderr)
    spills = re.findall(r"(\d+) bytes spill stores", run.stderr)
    if run.returncode or regs is None:
        return ""
    return f"registers={regs.group(1)} spills={sum(int(v) for v in spills)}"


def main() -> None:
    os.environ.pop("TRITON_INTERPRET", None)
    import triton  # before the kernels: they then stay compiled
    from triton.backends.compiler import GPUTarget
    from triton.compiler import ASTSource

    from torchsar import _gpu_kernels as gk

    target = GPUTarget("cuda", 90, 32)
    bh, bw = gk._CA_TILE
    variants = [("ring_ratio", gk._ring_ratio_kernel, {"BH": bh, "BW": bw}, 4)]
    for moments in (1, 2):
        for valid in (False, True):
            consts = {"MOMENTS": moments, "VALID": valid, "BH": bh, "BW": bw}
            name = f"region_sums MOMENTS={moments} VALID={valid}"
            warps = gk.region_warps(valid)
            variants.append((name, gk._region_sums_kernel, consts, warps))
    decision = dict(zip(("BH", "BW"), gk._OS_TILE, strict=True))
    warps = gk._OS_DECISION_WARPS
    variants.append(("os_decision", gk._os_decision_kernel, decision, warps))
    for npad in (16, 64, 256):
        bh, bw, warps = gk.os_ratio_launch(npad, gpu=True)
        consts = {"NP": npad, "BH": bh, "BW": bw}
        variants.append((f"os_ratio NP={npad}", gk._os_ratio_kernel, consts, warps))
    for name, fn, constexprs, warps in variants:
        options = {"num_warps": warps, "enable_fp_fusion": False}  # as the launches
        kernel = triton.compile(
            ASTSource(fn, _signature(fn), constexprs), target=target, options=options
        )
        fma = len(re.findall(r"\bfma\.", kernel.asm["ptx"]))
        print(
            name, "ok", len(kernel.asm["cubin"]), f"bytes fma={fma}", _resources(kernel.asm["ptx"])
        )


if __name__ == "__main__":
    main()
