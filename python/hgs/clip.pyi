# Type stubs of hgs.clip (native OpenCLIP on user-supplied weights).
import os
from typing import Sequence, Union

import numpy as np
import numpy.typing as npt

class Model:
    embed_dim: int
    def __init__(self, path: Union[str, os.PathLike], precision: str = "f32") -> None: ...
    def describe(self) -> str: ...
    def embed_text(self, texts: Sequence[str]) -> npt.NDArray[np.float32]: ...  # [T, D]
    def embed_image(self, image: npt.NDArray) -> npt.NDArray[np.float32]: ...  # [D]
    def dense_features(self, image: npt.NDArray, input_size: int = 448) -> npt.NDArray[np.float32]: ...  # [h, w, D]
