"""Reading and writing the ``.npz`` scene file (format in ``docs/scene-format.md``).

The file is a NumPy zip archive; the JSON header is stored as a uint8 array named ``header``.
Loading uses ``allow_pickle=False`` and refuses object arrays, so a scene file can never run
code. Every failure becomes a ``SceneError`` with the field (or the file) named.
"""

from __future__ import annotations

import json
import os
import zipfile

import numpy as np

from .scene import Scene, SceneError, scene_from_dict

MAX_HEADER_BYTES = 64 << 20
MAX_ARRAY_BYTES = 16 << 30  # total uncompressed arrays a scene file may declare


def encode_header(header: dict) -> np.ndarray:
    """The header as the uint8 array stored under ``header``."""
    return np.frombuffer(json.dumps(header, separators=(",", ":")).encode("utf-8"), dtype=np.uint8)


#: members at least this large (bytes) are stored uncompressed when deflate would save less than
#: STORE_BELOW_SAVING of their size (mesh floats: normals, uvs, positions): reading a stored
#: member is a copy, inflating one runs at ~0.3 GB/s — 0.3 s of a 1M-triangle scene's start-up
STORE_MIN_BYTES = 1 << 20
STORE_BELOW_SAVING = 0.25
_SAMPLE_BYTES, _SAMPLES = 1 << 16, 8


def _deflate_saving(raw: memoryview) -> float:
    """The fraction of ``raw`` deflate (level 6, as np.savez_compressed) would save, estimated
    from _SAMPLES evenly spread 64 KiB slices (compressing the whole member would double the
    export time of a big mesh)."""
    import zlib

    n = len(raw)
    step = max((n - _SAMPLE_BYTES) // max(_SAMPLES - 1, 1), 1)
    starts = range(0, max(n - _SAMPLE_BYTES, 0) + 1, step)
    total = packed = 0
    for start in list(starts)[:_SAMPLES]:
        chunk = raw[start:start + _SAMPLE_BYTES]
        total += len(chunk)
        packed += len(zlib.compress(chunk, 6))
    return 1.0 - packed / max(total, 1)


def save_scene(path: str | os.PathLike, header: dict, arrays: dict[str, np.ndarray], compress: bool = True) -> None:
    """Write a scene file. ``arrays`` maps names like ``mesh0.positions`` to numeric arrays.

    With ``compress`` (default) members are deflated, except big ones that deflate poorly
    (``STORE_MIN_BYTES``, ``STORE_BELOW_SAVING``), which are stored: any zip reader (np.load,
    ``read_scene_arrays``) reads both, so the format is unchanged (docs/scene-format.md)."""
    payload = {"header": encode_header(header)}
    for name, a in arrays.items():
        a = np.asarray(a)
        if a.dtype.kind not in "biuf":
            raise SceneError(name, f"cannot store dtype {a.dtype} (numeric arrays only)")
        payload[name] = a
    tmp = f"{os.fspath(path)}.tmp"
    with zipfile.ZipFile(tmp, "w", allowZip64=True) as z:
        for name, a in payload.items():
            a = np.ascontiguousarray(a)
            method = zipfile.ZIP_STORED
            if compress:
                raw = memoryview(a.reshape(-1).view(np.uint8))
                big_and_dense = a.nbytes >= STORE_MIN_BYTES and _deflate_saving(raw) < STORE_BELOW_SAVING
                method = zipfile.ZIP_STORED if big_and_dense else zipfile.ZIP_DEFLATED
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = method
            with z.open(info, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, a, allow_pickle=False)
    os.replace(tmp, path)  # never leave a half-written scene behind


def _available_memory() -> int | None:
    """Bytes the OS says can still be allocated (Linux MemAvailable); None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _array_budget() -> int:
    avail = _available_memory()
    return MAX_ARRAY_BYTES if avail is None else min(MAX_ARRAY_BYTES, int(0.8 * avail))


#: bytes inflated per call: big enough that zlib runs long without the GIL, small enough that
#: zipfile's bytes objects stay cheap to copy (one copy per chunk into the array)
_READ_CHUNK = 4 << 20


def _read_member(z: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One ``.npy`` member, after checking that the shape its header declares matches the size
    the archive declares (a lying header cannot make us allocate more than the archive holds).

    The data are read into the array in 4 MiB calls (numpy's reader inflates 256 KiB at a time,
    with the GIL held between chunks): zlib inflates each chunk without the GIL, so
    ``read_scene_arrays`` inflates big members on several threads at once."""
    name = info.filename[:-4]
    with z.open(info) as f:
        try:
            version = np.lib.format.read_magic(f)
            # (numpy's public readers: its private _read_array_header moved in numpy 2, which
            # Blender 5.1+ bundles; format 3.0 only differs for non-Latin-1 field names)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f, max_header_size=10000)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f, max_header_size=10000)
            else:
                raise ValueError(f"format version {version[0]}.{version[1]} is not one DRT writes")
        except (ValueError, SyntaxError, TypeError) as e:
            raise SceneError(name, f"is not a valid .npy array ({e})") from None
        if dtype.hasobject:
            raise SceneError(name, "is an object array, which would need pickle to load: refused")
        count = 1
        for s in shape:
            count *= int(s)
        data_bytes = info.file_size - f.tell()
        if count * dtype.itemsize != data_bytes:
            raise SceneError(
                name, f"declares shape {shape} of {dtype} ({count * dtype.itemsize} bytes) but holds {data_bytes} bytes"
            )
        out = np.empty(count, dtype=dtype)
        view = memoryview(out.view(np.uint8))
        for start in range(0, data_bytes, _READ_CHUNK):
            part = view[start:start + _READ_CHUNK]
            if f.readinto(part) != len(part):
                raise SceneError(name, "ends before its declared size")
        f.read(1)  # reach the end of the member: zipfile checks its CRC there
    if fortran:
        return out.reshape(shape[::-1]).transpose()
    return out.reshape(shape)


#: members at least this large (bytes, uncompressed) are read on worker threads
PARALLEL_MIN_BYTES = 1 << 20


def _read_members(path: str, z: zipfile.ZipFile, infos: list) -> list[np.ndarray]:
    """The members ``infos`` of archive ``z`` (at ``path``), in order; big ones are inflated on
    threads, each with its own ZipFile (zlib releases the GIL: a 1M-triangle scene's ~80 MB of
    mesh arrays read in about half the wall time on two cores)."""
    big = [i for i, info in enumerate(infos) if info.file_size >= PARALLEL_MIN_BYTES]
    workers = min(len(big), os.cpu_count() or 1, 4)
    if workers < 2:
        return [_read_member(z, info) for info in infos]
    from concurrent.futures import ThreadPoolExecutor

    def read_one(info):
        with zipfile.ZipFile(path) as own:
            return _read_member(own, info)  # the same entry (names may repeat in a bad file)

    with ThreadPoolExecutor(workers) as pool:
        futures = {i: pool.submit(read_one, infos[i]) for i in big}
        out = [None if i in futures else _read_member(z, info) for i, info in enumerate(infos)]
        for i, fut in futures.items():
            out[i] = fut.result()
    return out


def read_scene_arrays(path: str | os.PathLike) -> tuple[dict, dict[str, np.ndarray]]:
    """Read the header dict and arrays without validating their meaning.

    Memory stays bounded by what the archive declares: before anything is decompressed, the
    members' declared sizes must fit ``MAX_ARRAY_BYTES`` (and 80 % of the available memory), and
    every ``.npy`` header's shape must match its member's size (no zip bombs, no lying shapes).
    """
    p = os.fspath(path)
    if not os.path.isfile(p):
        raise SceneError("file", f"{p} does not exist")
    try:
        with zipfile.ZipFile(p) as z:
            if any(not i.filename for i in z.infolist()):
                # (Python 3.11's ZipInfo.is_dir raised IndexError on it; 3.13's does not)
                raise SceneError("file", f"{p} has a member with an empty name")
            infos = [i for i in z.infolist() if not i.is_dir()]
            names = [i.filename[:-4] if i.filename.endswith(".npy") else i.filename for i in infos]
            if "header" not in names:
                raise SceneError("header", f"{p} has no 'header' entry (is it a DRT scene file?)")
            for i, name in zip(infos, names):
                if not i.filename.endswith(".npy"):
                    raise SceneError(name, "is not a .npy array (a scene archive holds only .npy members)")
            header_info = infos[names.index("header")]
            if header_info.file_size > MAX_HEADER_BYTES + 1024:
                raise SceneError("header", f"is larger than {MAX_HEADER_BYTES} bytes")
            total, budget = sum(i.file_size for i in infos), _array_budget()
            if total > budget:
                raise SceneError("file", f"{p} declares {total / 2**30:.2f} GiB of arrays, more than the {budget / 2**30:.2f} GiB allowed")
            arrays = dict(zip(names, _read_members(p, z, infos)))
    except SceneError:
        raise
    except MemoryError:
        raise SceneError("file", f"{p} does not fit in the available memory") from None
    except Exception as e:  # noqa: BLE001 - zipfile/numpy raise many types on corrupt archives
        # (BadZipFile, EOFError, zlib.error, struct.error, ...)
        raise SceneError("file", f"{p} is not a readable scene archive ({type(e).__name__}: {e})") from None
    raw = arrays.pop("header")
    if raw.dtype != np.uint8 or raw.ndim != 1:
        raise SceneError("header", f"must be a 1-D uint8 array of UTF-8 JSON, got {raw.dtype} {raw.shape}")
    if raw.size > MAX_HEADER_BYTES:
        raise SceneError("header", f"is larger than {MAX_HEADER_BYTES} bytes")
    try:
        header = json.loads(raw.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise SceneError("header", f"is not valid UTF-8 JSON ({e})") from None
    except RecursionError:
        raise SceneError("header", "is nested too deeply") from None
    except ValueError as e:  # e.g. an integer with more digits than Python converts
        raise SceneError("header", f"is not valid JSON ({e})") from None
    if not isinstance(header, dict):
        raise SceneError("header", "must be a JSON object")
    return header, arrays


def load_scene(path: str | os.PathLike) -> Scene:
    """Load and validate a scene file."""
    header, arrays = read_scene_arrays(path)
    try:
        return scene_from_dict(header, arrays)
    except SceneError:
        raise
    except RecursionError:
        raise SceneError("header", "is nested too deeply") from None
