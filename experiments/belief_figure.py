"""One episode's belief, touch by touch, as a figure (the planner over skills, ``plan``; any
strategy that plays skills records its belief):

    python -m peg_ctrl.experiments.belief_figure runs/contact_real_plan/episodes/KEY --out belief.png
"""

from peg_ctrl.experiments.report.skills import main

if __name__ == "__main__":
    raise SystemExit(main())
