"""From measurements to a calibrated robot: identification (model, LM, statistics), diagnosis
of what the geometry leaves, tool and base recalibration, and the Calibration type itself."""
