"""Team agents: tabular team Q-learning and a factored deep Q-network."""
