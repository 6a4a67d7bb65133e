"""The simulator: Open3D ray-cast camera, voxelisation, pose sampling and agent motion."""
