"""A folder of plan files of buildings in no corpus, for the tests of the workflows that read one's own plans."""

from pathlib import Path


def write_plan_folder(tmp_path: Path) -> Path:
    """``tmp_path/plans``: two plans of buildings in no corpus, a generated office map as a PNG (0.025 m pixels,
    so read at half size) and a hall map as a ROS map (0.05 m cells)."""
    import numpy as np
    from PIL import Image

    from ogm_ppl import Grid
    from ogm_ppl.datasets.mapgen import generate_map
    from ogm_ppl.rosmap import save_ros_map

    d = tmp_path / "plans"
    d.mkdir()
    office = generate_map("office", (80, 80), seed=3)
    Image.fromarray(np.where(office, 0, 255).astype(np.uint8)).resize((160, 160), Image.NEAREST).save(d / "office.png")
    hall = generate_map("hall", (80, 80), seed=4)
    save_ros_map(d / "hall.yaml", hall[::-1].astype(float).ravel(), Grid(hall.shape, resolution=0.05), sidecar=False)
    return d
