"""ULog writing: a streaming ULog writer and the rig's own log (``rig.ulg``: ground truth,
sensors as delivered, actuators, events) under PX4's topic names.

May import: quad_model. Nothing else of the rig.
"""
