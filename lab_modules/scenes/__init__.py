"""The 3D views of the rigs (viser scene nodes), animated from a loop's latest sample."""
