# Type stubs of hgs.sam (native SAM on user-supplied weights).
import os
from typing import Any, Dict, List, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

class Model:
    def __init__(self, path: Union[str, os.PathLike], precision: str = "f32") -> None: ...
    def describe(self) -> str: ...
    def embed(self, image: npt.NDArray) -> npt.NDArray[np.float32]: ...  # [grid, grid, C]
    def predict(self, image: npt.NDArray, points: Sequence[Tuple[float, float]] = ..., labels: Sequence[int] = ...,
                boxes: Sequence[Tuple[float, float, float, float]] = ...
                ) -> Tuple[npt.NDArray[np.bool_], npt.NDArray[np.float32]]: ...  # [T, H, W], [T]
    def generate(self, image: npt.NDArray, points_per_side: int = 32, pred_iou_thresh: float = 0.88,
                 stability_score_thresh: float = 0.95, min_mask_region_area: int = 0) -> List[Dict[str, Any]]: ...
