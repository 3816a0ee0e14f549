"""Torch-batched controllers: optimization fabrics, A* + PID base tracking, gripper logic."""
