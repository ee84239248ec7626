"""LIBERO simulator support: installation, scripted expert, demonstration recording."""
