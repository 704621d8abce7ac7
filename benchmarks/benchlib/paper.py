"""The paper's numbers, stated once (Track3D paper, i9-9900K + RTX 2080Ti).

TABLE2: the rows of Table 2 (None: the paper gives no number). The 3D tracking baseline row
is SiamFC + minimum enclosing box + fusion (paper V-A). TABLE3_NO_CATEGORY: A3BoxNet trained
without the category vector (Table 3; the row with it is TABLE2["A3BoxNet"]).
"""
from __future__ import annotations

__all__ = ["COLUMNS", "TABLE2", "TABLE3_NO_CATEGORY", "fusion_gain"]

COLUMNS = ("AO_2d", "ACE_2d(px)", "AO_bev", "AO_3d", "ACE_3d(m)", "FPS")
TABLE2 = {
    "SiamFC": {"AO_2d": 0.513, "ACE_2d(px)": 29.986, "AO_bev": None, "AO_3d": None, "ACE_3d(m)": None,
               "FPS": 101.3},
    "A3BoxNet": {"AO_2d": None, "ACE_2d(px)": None, "AO_bev": 0.798, "AO_3d": 0.721, "ACE_3d(m)": 0.345,
                 "FPS": 281.5},
    "3D Tracking Baseline": {"AO_2d": 0.568, "ACE_2d(px)": 23.767, "AO_bev": 0.309, "AO_3d": 0.165,
                             "ACE_3d(m)": 0.876, "FPS": 103.1},
    "Track3D": {"AO_2d": 0.541, "ACE_2d(px)": 26.741, "AO_bev": 0.756, "AO_3d": 0.669, "ACE_3d(m)": 0.570,
                "FPS": 77.0},
}
TABLE3_NO_CATEGORY = {"AO_bev": 0.792, "AO_3d": 0.715, "ACE_3d(m)": 0.316}


def fusion_gain(row: str) -> tuple[float, float]:
    """(AO_2d gain, gain in %) of a fused Table 2 row over the SiamFC row: the paper's claim
    that fusion improves the 2D tracker."""
    off, on = TABLE2["SiamFC"]["AO_2d"], TABLE2[row]["AO_2d"]
    return on - off, 100.0 * (on - off) / off
