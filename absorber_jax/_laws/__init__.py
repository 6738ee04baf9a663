"""Contact and friction laws, and the smoothing functions they use."""
