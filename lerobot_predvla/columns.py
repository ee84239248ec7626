"""Column names and layout constants every layer shares (one definition each); imports nothing of the package.

The cached front-end columns that `predvla convert` writes and every policy reads, and LIBERO's layout: its suites,
the Panda's state and action sizes (Table 1's defaults) and its two cameras under each of their names.
"""

# Cached front-end columns written by the converter (`predvla convert`).
OBS_VISION_FEATURES = "observation.vision_features"
OBS_LANGUAGE_FEATURES = "observation.language_features"
FRONTEND_META_DIR = "meta/predvla_frontend"  # the front-end artefact copy a converted dataset carries
# Set by the `predvla_libero` environment: 1 where the step's camera images are freshly rendered.
OBS_IMAGE_FRESH = "observation.image_fresh"

# LIBERO's suites (folders of its hdf5 demonstrations, `--env.task` of its LeRobot env).
SUITES = ("libero_spatial", "libero_object", "libero_goal", "libero_10")
# LIBERO's Panda: joint positions, gripper finger positions, delta end-effector action.
JOINT_DIM, GRIPPER_DIM, ACTION_DIM = 7, 2, 7
LEROBOT_LIBERO_STATE_DIM = 8  # LeRobot's LiberoProcessorStep: eef position 3 + axis-angle 3 + gripper 2
# LIBERO's two cameras (agent view, wrist) by their LeRobot keys (as LeRobot's LIBERO env names them): their keys in
# LIBERO's hdf5 demonstrations and their names in the simulator.
HDF5_CAMERAS = {"observation.images.image": "agentview_rgb", "observation.images.image2": "eye_in_hand_rgb"}
SIM_CAMERAS = {"observation.images.image": "agentview", "observation.images.image2": "robot0_eye_in_hand"}
