"""Scene-constrained human motion synthesis (paper Sec. 4.2.3, supplementary D.3, Table 5).

A walk from a start to a goal across a furnished room, optimised so that the body's last-frame pelvis reaches the
goal and the body does not pass through the scene's point cloud. The paper optimises DartControl's latent noise;
that pretrained model is not available here, so `walk` provides a differentiable procedural walking model
(`walk.WalkModel`: per-primitive heading change and speed, per-frame pose residuals on a periodic walk cycle,
foot-locked root, feet on the floor) with the objective's helpers (`walk.jerk`, `walk.foot_skate`, `walk.pose_prior`)
and `walk.render_strip` for pictures.
"""
