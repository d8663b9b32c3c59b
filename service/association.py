"""The paper's identity rule for detector mode now lives in ``posenet.boxes``; this name stays for old imports."""

from posenet.boxes import assign, ground_truth_ids, mean_view_iou

__all__ = ["assign", "ground_truth_ids", "mean_view_iou"]
