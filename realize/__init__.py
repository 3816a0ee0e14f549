"""realize: physically grounded realizations of symbolic robot plans.

Samples N parameter vectors of a symbolic plan, simulates all N realizations at once in a
batched ManiSkill/SAPIEN scene with the robot's own controllers, and refines the sampling
distribution by cross-entropy optimization.
"""

from realize.reproducible import pin_cpu_math

pin_cpu_math()  # before any torch op: the same torch/MKL kernel paths on every x86-64 CPU with AVX2

__version__ = "0.1.0"
