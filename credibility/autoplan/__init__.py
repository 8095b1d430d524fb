"""An automatic test plan: the segments the paper's tests need, found in a real PX4 log.

Writing a plan by hand means reading the flight's timeline for the spans each kind of test
needs: the vehicle at rest, armed at idle and in steady hover for the sensor noise (η_p),
set-point steps for the step responses (η_t), the pilot's inputs for the frequency
responses (η_f). Each finder below looks for one of them with a stated criterion and says
what it found in numbers; what a log cannot give (no GNSS, a slow logging rate, never
airborne) becomes a ``[[not_scorable]]`` entry with the reason. :func:`draft_plan` gathers
them, :func:`plan_toml` writes the plan a user can read, edit and score.
"""

from credibility.autoplan.plan_file import draft_plan, plan_toml, write_plan

__all__ = ["draft_plan", "plan_toml", "write_plan"]
