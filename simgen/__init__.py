"""simgen: MuJoCo synthetic traffic scenes and dataset generator."""
