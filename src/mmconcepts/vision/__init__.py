"""Vision: image data and image descriptors (the image modality of thesis chapter 6, section 6.5.3).

Contents
--------
data
    :class:`ImageSet` (float RGB images in [0, 1], labels, views, categories, paths);
    loaders for the generic image layout (:func:`load_image_folder`, ``labels.csv`` with
    ``file,labels[,view]``), ETH-80 (:func:`load_eth80`) and COIL-20 (:func:`load_coil20`).
features
    Bags of visual words as scikit-learn transformers fit on training images only:
    :class:`ColorHistograms` (HSV colours of SLIC superpixels), :class:`KeypointBag`
    (dense SIFT-like descriptors, standing in for SURF), :class:`MidFeatures` (pairs and
    triplets of neighbouring words), and the front object :class:`ImageFeatures`
    returning named descriptor sets; :func:`stack_descriptors` combines them.
synthetic
    :func:`make_objects`, photos of parametric objects from many views, and
    :func:`write_image_folder`, the generic-layout writer.
"""

from __future__ import annotations

from .data import (
    ETH80_CATEGORIES,
    LABELS_FILE,
    ImageSet,
    SkippedFile,
    as_rgb_image,
    check_images,
    load_coil20,
    load_eth80,
    load_image,
    load_image_folder,
)
from .features import (
    DESCRIPTORS,
    THESIS_DESCRIPTORS,
    ColorHistograms,
    ImageFeatures,
    KeypointBag,
    LocalFeatures,
    MidFeatures,
    dense_sift,
    n_tuple_columns,
    neighbour_tuples,
    stack_descriptors,
    superpixel_colors,
    tuple_columns,
)
from .synthetic import (
    FAMILIES,
    GENERATOR_VERSION,
    TEXTURES,
    ViewParams,
    image_statistics,
    make_objects,
    write_image_folder,
)

__all__ = [
    "DESCRIPTORS",
    "ETH80_CATEGORIES",
    "FAMILIES",
    "GENERATOR_VERSION",
    "LABELS_FILE",
    "TEXTURES",
    "THESIS_DESCRIPTORS",
    "ColorHistograms",
    "ImageFeatures",
    "ImageSet",
    "KeypointBag",
    "LocalFeatures",
    "MidFeatures",
    "SkippedFile",
    "ViewParams",
    "as_rgb_image",
    "check_images",
    "dense_sift",
    "image_statistics",
    "load_coil20",
    "load_eth80",
    "load_image",
    "load_image_folder",
    "make_objects",
    "n_tuple_columns",
    "neighbour_tuples",
    "stack_descriptors",
    "superpixel_colors",
    "tuple_columns",
    "write_image_folder",
]
