"""File I/O, kept apart from the maths: images, meshes, scenes."""
