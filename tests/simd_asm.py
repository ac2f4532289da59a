"""What the SIMD tests read off a compiled loop's assembly, whatever the CPU's vector width.

LLVM picks the width itself: on a CPU with AVX-512 it may still prefer 256-bit vectors (its ``rocketlake`` and
``skylake-avx512`` tunings do), so a loop vectorised on ymm registers is as much SIMD code as one on zmm. A test
therefore counts packed double-precision instructions on either, and never expects one width.
"""

VECTOR_REGISTERS = ("ymm", "zmm")  # 256- and 512-bit; xmm alone (128-bit) is not counted as vectorised here


def packed_double_ops(asm: str) -> list[str]:
    """The mnemonics of the packed double-precision instructions (``v...pd``) on 256- or 512-bit registers."""
    out = []
    for line in asm.splitlines():
        parts = line.split()
        if parts and parts[0].endswith("pd") and any(reg in line for reg in VECTOR_REGISTERS):
            out.append(parts[0])
    return out
