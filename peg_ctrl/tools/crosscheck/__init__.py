"""The contact cross-check (``peg-sim crosscheck``): the situations that set the studies' force
numbers, run in MuJoCo and in Drake on one rig, so that a force the studies report is the
contact's and not one engine's solver's (docs/physics.md, "Cross-check against Drake").

- :mod:`.situations`: the situations (slides down the bore, landings, a side touch, wedging and
  entry pushes) and the hand laws that drive them;
- :mod:`.rig`: the rig both engines build (geometry from the physics profile, the hand from the
  featured study's controller), the engine interface and the loop that records a trace;
- :mod:`.mujoco_rig`, :mod:`.drake_rig`: the two engines (and MuJoCo with the gripper's grasp);
- :mod:`.battery`: the contact models compared and the numbers of a run;
- :mod:`.report`: the record, the tables and the plots.

Drake is optional: ``pip install 'peg-ctrl[crosscheck]'``.
"""
