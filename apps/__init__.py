"""Applications built on volsmpl: hoi, egohmr, motion, selfpen."""
