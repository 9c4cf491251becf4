"""docs/contact_poses.png: 12 training self-contact poses (volsmpl.body.poses, seed 5, mean shape), their
contact vertices (volsmpl.body.contact_regions) in red. Run: python tools/contact_poses_figure.py"""
import numpy as np, torch, volsmpl
from volsmpl.body.poses import sample_contact_euler
from volsmpl.body.poses import euler_to_body_pose
from volsmpl.body.contact_regions import contact_vertices
from volsmpl.viz.render import render_mesh, grid, save_png
torch.set_num_threads(1)
body = volsmpl.create_body()
pose = euler_to_body_pose(sample_contact_euler(12, seed=5))
with torch.no_grad():
    v = body(body_pose=pose, betas=torch.zeros(12, body.num_betas)).vertices
mask = contact_vertices(v, body.v_template)
faces = np.asarray(body.faces)
imgs, labels = [], []
for i in range(12):
    fc = np.tile(np.array([0.75, 0.75, 0.78]), (len(faces), 1))
    hit = mask[i].numpy()[faces].any(1)
    fc[hit] = [0.9, 0.2, 0.2]
    imgs.append(render_mesh(v[i].numpy(), faces, face_colors=fc, size=256, yaw=25, pitch=10))
    labels.append(f"{int(mask[i].sum())} contact v.")
save_png("docs/contact_poses.png", grid(imgs, labels, cols=6))
print("ok")
