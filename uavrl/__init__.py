"""uavrl: learning spectrum sharing and task allocation in UAV networks with TorchRL."""
__version__ = "0.1.0"
