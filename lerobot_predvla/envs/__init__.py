"""LeRobot env types of the plugin (`--env.type=predvla_libero`)."""
