"""The scene catalog: the registry (registry.py), the validation scenes (membranes.py), the robotic
scenes (robot_scenes.py) and their time schedules (robots.py). Importing ``snapmem`` registers every
scene (through scenes.py)."""
