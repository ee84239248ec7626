"""Small helpers shared across the package: atomic files, checkpoint paths, versions, parameter counts."""
