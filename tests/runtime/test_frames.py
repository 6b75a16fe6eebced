"""The frame readers: one of image folders, one of videos; lenient for the loop, strict for offline commands."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from runtime.frames import FolderSource, SourceError, VideoSource, open_source, read_frames


def _image(k: int, size=(32, 24)) -> np.ndarray:
    """An RGB image whose red channel says ``k`` and whose blue channel is 0 (catches a BGR mix-up)."""
    img = np.zeros((size[1], size[0], 3), np.uint8)
    img[..., 0] = 10 * k + 5
    img[..., 1] = 100
    return img


def _folder(tmp_path, n: int = 4):
    folder = tmp_path / "frames"
    folder.mkdir()
    for k in range(n):
        cv2.imwrite(str(folder / f"f{k:03d}.png"), cv2.cvtColor(_image(k), cv2.COLOR_RGB2BGR))
    (folder / "notes.txt").write_text("not an image, not listed")
    return folder


def _video(tmp_path, n: int = 5):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 25.0, (32, 24))
    for k in range(n):
        writer.write(cv2.cvtColor(_image(k), cv2.COLOR_RGB2BGR))
    writer.release()
    return path


def test_folder_in_name_order_as_rgb_with_a_limit(tmp_path):
    folder = _folder(tmp_path)
    frames = list(read_frames(folder))
    assert [int(f[0, 0, 0]) for f in frames] == [5, 15, 25, 35] and all(f[0, 0, 2] == 0 for f in frames)
    assert len(list(read_frames(folder, 2))) == 2
    source = open_source(str(folder), fps=10.0)
    assert isinstance(source, FolderSource) and source.fps == 10.0
    assert [int(f[0, 0, 0]) for f in source.frames()] == [5, 15, 25, 35]


def test_video_as_rgb_with_a_limit(tmp_path):
    path = _video(tmp_path)
    frames = list(read_frames(path))
    assert [int(f[0, 0, 0]) for f in frames] == [5, 15, 25, 35, 45] and frames[0].shape == (24, 32, 3)
    assert len(list(read_frames(path, 3))) == 3
    source = open_source(str(path))
    assert isinstance(source, VideoSource) and source.fps == pytest.approx(25.0)
    assert len(list(source.frames())) == 5
    source.close()


def test_unreadable_image_is_none_for_the_loop_and_an_error_offline(tmp_path):
    folder = _folder(tmp_path, 3)
    (folder / "f001.png").write_bytes(b"not a png")
    assert [f is None for f in FolderSource(folder).frames()] == [False, True, False]
    with pytest.raises(SourceError, match=r"f001\.png: not a readable image"):
        list(read_frames(folder))


def test_strict_reading_refuses_a_change_of_size(tmp_path):
    folder = _folder(tmp_path, 2)
    cv2.imwrite(str(folder / "f002.png"), np.zeros((10, 10, 3), np.uint8))
    with pytest.raises(SourceError, match=r"f002\.png: frame size 10x10, expected 32x24"):
        list(read_frames(folder))


@pytest.mark.parametrize("make,expect", [
    (lambda p: p / "none", "no such video file or image folder"),
    (lambda p: p, "no images"),
    (lambda p: (p / "x.avi").write_bytes(b"\0" * 64) and p / "x.avi", "OpenCV"),
], ids=["missing", "empty-folder", "not-a-video"])
def test_bad_sources_are_one_line(tmp_path, make, expect):
    with pytest.raises(SourceError, match=expect) as e:
        list(read_frames(make(tmp_path)))
    assert "\n" not in str(e.value)
