# Type stubs of the package hgs (the C++ module _hgs and the Python wrappers of __init__.py), for editors and
# type checkers. Shapes in the comments: N Gaussians, L = objects + 1 labels, D language dimensions.
import os
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

from . import clip as clip
from . import sam as sam

__version__: str
PathLike = Union[str, os.PathLike]
ViewKey = Union[int, str]

class Error(RuntimeError):
    """A user-facing error of the hgs library: one line naming the file or option and the problem."""

class View:
    index: int
    name: str
    stem: str
    width: int
    height: int
    size: Tuple[int, int]
    fx: float
    fy: float
    cx: float
    cy: float
    K: npt.NDArray[np.float64]  # [3, 3]
    R: npt.NDArray[np.float64]  # [3, 3] world -> camera
    t: npt.NDArray[np.float64]  # [3]
    pose: npt.NDArray[np.float64]  # [4, 4] world -> camera
    camera_center: npt.NDArray[np.float64]  # [3]
    is_test: bool
    image_path: str

class Scene:
    root: str
    downscale: int
    views: List[View]
    train_indices: List[int]
    test_indices: List[int]
    has_masks: bool
    has_features: bool
    split_source: str
    warnings: List[str]
    points: npt.NDArray[np.float32]  # [P, 3]
    point_colors: npt.NDArray[np.float32]  # [P, 3]
    object_names: Dict[int, str]
    text_embeddings: Dict[str, npt.NDArray[np.float32]]  # phrase -> [D]
    num_objects: int
    @staticmethod
    def load(path: PathLike, downscale: int = 1) -> Scene: ...
    def __len__(self) -> int: ...
    def view(self, view: ViewKey) -> View: ...
    def index(self, view: ViewKey) -> int: ...
    def image(self, view: ViewKey) -> npt.NDArray[np.uint8]: ...  # [H, W, 3]
    def mask(self, view: ViewKey) -> Optional[npt.NDArray[np.int32]]: ...  # [H, W]
    def confidence(self, view: ViewKey) -> Optional[npt.NDArray[np.float32]]: ...  # [H, W]
    def features(self, view: ViewKey, upsample: bool = True) -> Optional[npt.NDArray[np.float32]]: ...  # [H, W, D]

class Model:
    n: int
    sh_degree: int
    is_hybrid: bool
    method: str
    means: npt.NDArray[np.float32]  # [N, 3] view
    log_scales: npt.NDArray[np.float32]  # [N, 3] view
    scales: npt.NDArray[np.float32]  # [N, 3] copy
    rotations: npt.NDArray[np.float32]  # [N, 4] (w, x, y, z) view
    opacity_logits: npt.NDArray[np.float32]  # [N] view
    opacities: npt.NDArray[np.float32]  # [N] copy
    sh: npt.NDArray[np.float32]  # [N, S, 3] view
    object_probs: npt.NDArray[np.float32]  # [N, L] view (hybrid)
    object_ids: npt.NDArray[np.int32]  # [N] copy (hybrid)
    language: npt.NDArray[Any]  # [N, D] float16 or float32 view (hybrid)
    extras: Dict[str, npt.NDArray[Any]]
    train_stats: Dict[str, Any]  # set by hgs.train
    near_plane: float  # set by Model.load (config.json beside the PLY) and hgs.train; hgs.render culls at it
    def __init__(self, means: npt.NDArray[np.float32], log_scales: npt.NDArray[np.float32],
                 rotations: npt.NDArray[np.float32], opacity_logits: npt.NDArray[np.float32],
                 sh: npt.NDArray[np.float32], extras: Dict[str, npt.NDArray[np.float32]] = ...) -> None: ...
    @staticmethod
    def load(path: PathLike) -> Model: ...
    def save(self, path: PathLike) -> str:
        """Writes path (.ply) or path/point_cloud.ply with a config.json, the folder replaced as a whole (its other
        files kept): killed at any moment it holds the old model or the new one. hgs.Error naming the array when one
        holds NaN or infinite values (nothing written)."""
    def copy(self) -> Model: ...  # with the instance's near_plane
    def select(self, objects: Sequence[int], remove: bool = False) -> Model: ...  # with the instance's near_plane
    def __len__(self) -> int: ...

class StepInfo:
    loss: float
    terms: Dict[str, float]
    psnr: float
    num_gaussians: int
    ms: float
    densified: bool
    times: Dict[str, float]

class Trainer:
    """One call at a time: step / run / finish / load_checkpoint while another thread is in one of them raise
    hgs.Error ("Trainer.step: already running in another thread (Trainer.run)"); model, iteration and
    save_checkpoint wait for a running step (refused while run() runs in another thread; from its on_step they go
    ahead)."""
    iteration: int
    step_views: int
    iters: int
    model: Model  # a copy, with the run's near_plane
    config_json: str
    def __init__(self, scene: Scene, method: str = "hybrid", iters: int = 30000, options: Dict[str, Any] = ...,
                 progress: bool = False) -> None: ...
    def step(self) -> StepInfo:
        """One training step of step_views views. hgs.Error once `iters` images are seen ("Trainer.step: the run's
        N images are done (iters=N)": the schedule ends there; finish() returns the model), and while another
        thread is in step / run / finish / load_checkpoint of this trainer."""
    def run(self, iters: int, out: str = "", save_every: int = 0, test_every: int = 0, resumed_from: str = "",
            on_step: Optional[Callable[[StepInfo, int, float], Optional[bool]]] = None) -> str:
        """The library's training run to `iters` images; on_step(step, iteration, loss_average) after every step,
        returning False ends it (None goes on). The final files of `out` are written as one change of the folder."""
    def finish(self) -> Model: ...  # with the run's near_plane
    def save_checkpoint(self, path: PathLike) -> None: ...
    def load_checkpoint(self, path: PathLike) -> None: ...

class QuerySession:
    """Safe to share between threads (a QueryResult too): calls on one session run one at a time."""
    def __init__(self, scene: Scene, model: Model, clip: str = "", near_plane: Optional[float] = None) -> None: ...
    def ask(self, text: str, min_relevancy: float = 0.0, fragment_margin: float = ...,
            anchor_support: float = 0.0) -> List[Dict[str, Any]]: ...
    def object_opacity(self, view: ViewKey, objects: Sequence[int]) -> npt.NDArray[np.float32]: ...
    def pixel_relevancy(self, view: ViewKey, text: str, relevancy: str = "objects") -> npt.NDArray[np.float32]: ...
    def object_name(self, id: int) -> str: ...
    def evaluate(self, protocol: str, mode: str = "both", relevancy: str = "objects", mask_threshold: float = 0.5,
                 overlay_dir: str = "", progress: bool = False, paper_map: bool = True, queries: str = "",
                 fragment_margin: float = ..., anchor_support: float = 0.0) -> str: ...

class QueryResult:
    text: str
    objects: List[Dict[str, Any]]  # {id, name, relevancy, cosine, chosen, anchor}, best first
    chosen: List[int]
    views: List[int]
    mask_threshold: float
    best: Dict[str, Any]
    masks: Dict[str, npt.NDArray[np.bool_]]  # view name -> [H, W]
    def opacity(self, view: ViewKey) -> npt.NDArray[np.float32]: ...  # [H, W]
    def mask(self, view: ViewKey, threshold: Optional[float] = None) -> npt.NDArray[np.bool_]: ...  # [H, W]
    def relevancy(self, view: ViewKey, relevancy: str = "objects") -> npt.NDArray[np.float32]: ...  # [H, W]
    def select(self, remove: bool = False) -> Model: ...
    def export(self, path: PathLike, remove: bool = False) -> str: ...

def render(model: Model, scene: Scene, view: ViewKey, *, depth: bool = True, objects: bool = True,
           language: bool = False, background: Union[None, float, Sequence[float]] = None,
           sh_degree: int = -1, near_plane: Optional[float] = None) -> Dict[str, npt.NDArray[np.float32]]: ...
def train(scene: Union[Scene, PathLike], out: Optional[PathLike] = None, method: str = "hybrid", iters: int = 30000,
          callback: Optional[Callable[[Dict[str, Any]], Optional[bool]]] = None, callback_every: int = 100,
          progress: bool = True, threads: Optional[int] = None, resume: Optional[PathLike] = None,
          test_every: int = 0, **options: Any) -> Model: ...
def query(model: Union[Model, PathLike], scene: Union[Scene, PathLike], text: str,
          views: Union[None, str, int, Iterable[ViewKey]] = None, min_relevancy: float = 0.0,
          mask_threshold: float = 0.5, clip: Optional[PathLike] = None,
          session: Optional[QuerySession] = None, fragment_margin: Optional[float] = None,
          anchor_support: float = 0.0) -> QueryResult: ...
def evaluate(model: Union[Model, PathLike], scene: Union[Scene, PathLike], protocol: str = "instances",
             mode: str = "both", relevancy: str = "objects", mask_threshold: float = 0.5,
             clip: Optional[PathLike] = None, overlays: Optional[PathLike] = None,
             progress: bool = False, paper_map: bool = True, queries: Optional[str] = None,
             fragment_margin: Optional[float] = None, anchor_support: float = 0.0) -> Dict[str, Any]: ...
def synth(out: PathLike, *, preset: str = "tabletop", seed: int = 1, views: int = 48, width: int = 320,
          height: int = 240, objects: int = 0, points: int = 30000, noise: str = "medium", feature_dim: int = 512,
          mask_ids: str = "consistent", mask_style: str = "label", surface_masks: bool = True,
          objects_only: bool = False, miss_rate: float = -1.0, small_miss_rate: float = -1.0, merge_rate: float = -1.0,
          split_rate: float = -1.0, depth: bool = False, supersample: int = 2, progress: bool = False) -> str: ...
def set_threads(n: int) -> None:
    """Worker threads of OpenMP, the element-wise pool and OpenBLAS: n in 1..max_threads(), else hgs.Error
    (TypeError for a non-int); the bound every command's --threads shares."""
def max_threads() -> int:
    """The most threads set_threads (and --threads) accept: 4x the hardware threads."""
def method_names() -> List[str]: ...
