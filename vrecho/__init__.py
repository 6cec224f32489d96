"""vrecho: audio-augmented 3D scene reconstruction."""
