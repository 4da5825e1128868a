"""The scene simulator's tasks: truth world, images, metadata, check points, lidar, reference."""
