"""realize: physically grounded realizations of symbolic robot plans.

Samples N parameter vectors of a symbolic plan, simulates all N realizations at once in a
batched ManiSkill/SAPIEN scene with the robot's own controllers, and refines the sampling
distribution by cross-entropy optimization.
"""

__version__ = "0.1.0"
