"""The UAV spectrum-sharing model: batched TorchRL environment, physics and exact optimum."""
from .config import ACTION_NAMES, NUM_ACTIONS, ModelConfig, make_config
from .env import UAVSpectrumEnv
from .grid import decode_joint_actions, joint_action_valid, joint_targets
from .optimum import optimum

__all__ = ["ACTION_NAMES", "NUM_ACTIONS", "ModelConfig", "make_config", "UAVSpectrumEnv", "decode_joint_actions", "joint_action_valid", "joint_targets", "optimum"]
