"""Files a job reads and writes: checkpoints (safetensors + JSON), output paths checked before the work and
written atomically, per-case records that make long jobs resumable, and the provenance every result records."""
from volsmpl.io.case_store import CaseStore, job_key
from volsmpl.io.checkpoint import CheckpointError, load_checkpoint, save_checkpoint
from volsmpl.io.outputs import check_writable, exclusive_folder, write_atomic
from volsmpl.io.provenance import git_commit, machine_info

__all__ = ["CaseStore", "CheckpointError", "check_writable", "exclusive_folder", "git_commit", "job_key",
           "load_checkpoint", "machine_info", "save_checkpoint", "write_atomic"]
