"""inspector: rollout inspector for world-action models on the SO-101 arm."""
