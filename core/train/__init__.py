"""Training of the learned volumes (paper Sec. 3.4), `volsmpl train`: configuration, the batches of each step
(bodies, query points, exact ground truth), the resumable training-state folders, and the loop."""
from volsmpl.train.config import TrainConfig
from volsmpl.train.loop import train

__all__ = ["TrainConfig", "train"]
