"""Simulators, one folder each (`sims/libero/`): installation, tasks, scripted expert, recording and the LeRobot env
type that evaluates in it. Nothing is imported here, so importing a simulator's light modules (its protocol
constants, its env config) never loads the simulator itself."""
