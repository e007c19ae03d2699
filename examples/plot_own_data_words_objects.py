"""
Which object does this word name? From folders of recordings to cross-modal matching
=====================================================================================

Spoken words and object photos recorded apart, paired by concept, then one multimodal
NMF learnt without the labels (thesis chapter 6). A held-out word is matched to the photo,
among one per concept, that it is closest to in the learnt space. Real FSDD digits and
ETH-80 photos (one concept per category) when ``$MMCONCEPTS_DATA_ROOT`` holds them, else
made-up syllable words and generated objects. For folders of your own, pass their paths
to :func:`~mmconcepts.multimodal.paired_dataset` (see the guide "Your own data").
"""

import tempfile

import matplotlib.pyplot as plt

from mmconcepts.datasets import find_dataset
from mmconcepts.multimodal import MultimodalNMF, crossmodal_distances, matching_success_rate, paired_dataset
from mmconcepts.sound import load_fsdd, load_generic_audio, make_syllable_words
from mmconcepts.vision import ImageSet, load_eth80, make_objects

if find_dataset("fsdd") and find_dataset("eth80"):
    words, photos = load_fsdd(find_dataset("fsdd")), load_eth80(find_dataset("eth80"))
    objects = ImageSet(photos.images, photos.categories, paths=photos.paths)  # concept = category
else:
    words = load_generic_audio(make_syllable_words(tempfile.mkdtemp() + "/words", n_per_word=24))
    objects = make_objects(8, 24, random_state=0)

# pair by concept (a random word <-> object correspondence), split by recording: 60/20/20
data = paired_dataset({"sound": words, "image": objects}, random_state=0)
X = data.features(random_state=1)  # HAC for sound, colour histograms for images, fitted on training
model = MultimodalNMF(50, max_iter=50, random_state=2).fit(X["train"])  # the labels are never seen

test, ref = data.indices("test"), data.indices("reference")
D = crossmodal_distances(model, {"sound": X["test"]["sound"]}, {"image": X["reference"]["image"]},
                         space="internal", metric="cosine")
accuracy = matching_success_rate(D, data.y[test], data.y[ref], random_state=3)
chance = 1 / len(data.concepts)
print(data)
print(f"word -> object: {accuracy:.2f} (chance {chance:.2f})")

fig, ax = plt.subplots(figsize=(5, 2))
ax.barh(["word -> object", "chance"], [accuracy, chance], color=["C0", "0.6"])
ax.set(xlim=(0, 1), xlabel="matching success rate")
plt.show()
