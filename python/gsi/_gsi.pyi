"""Type stubs of the extension module `gsi._gsi` (python/src/lib.rs). It speaks bytes;
`gsi/__init__.py` turns them into numpy arrays and back."""

from typing import Any, Callable, Dict, List, Optional, Tuple, Union

class Error(ValueError):
    """A file, an image or an option gsi refuses; the message is the command-line tool's."""

def encode(
    samples: bytes,
    bits: int,
    width: int,
    height: int,
    *,
    bpp: Optional[float] = ...,
    gaussians: Optional[int] = ...,
    target_psnr: Optional[float] = ...,
    effort: Optional[int] = ...,
    blend: str = ...,
    seed: int = ...,
    device: str = ...,
    progress: Optional[Callable[[Dict[str, Any]], None]] = ...,
) -> bytes: ...
def decode(
    data: bytes, width: Optional[int] = ..., height: Optional[int] = ..., float: bool = ...
) -> Tuple[bytearray, int, int]: ...
def enhance(
    data: bytes,
    *,
    iterations: Optional[int] = ...,
    exposure: Union[None, float, str] = ...,
    experts: Optional[int] = ...,
    learning_rate: Optional[float] = ...,
    weights: Optional[List[float]] = ...,
    tone: Optional[float] = ...,
    local: bool = ...,
    denoise: bool = ...,
    force: bool = ...,
    discard_original: bool = ...,
    apply_from: Optional[bytes] = ...,
    seed: int = ...,
    device: str = ...,
    progress: Optional[Callable[[Dict[str, Any]], None]] = ...,
) -> Tuple[bytes, Optional[str]]: ...
def revert(data: bytes) -> bytes: ...
def info(data: bytes) -> str: ...
def read(data: bytes) -> Dict[str, Any]: ...
def render(
    width: int,
    height: int,
    blend: str,
    cov_param: str,
    positions: bytes,
    cov: bytes,
    colors: bytes,
    opacity: Optional[bytes],
    tone: Optional[Tuple[int, List[int]]],
    out_width: Optional[int] = ...,
    out_height: Optional[int] = ...,
    float: bool = ...,
) -> Tuple[bytearray, int, int]: ...
