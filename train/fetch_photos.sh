#!/usr/bin/env bash
# Collects the photographs used as photo textures in training into one folder
# (the PHOTOS of models/README.md's commands), from Debian 12 packages fetched
# with `apt-get download` (no root needed, nothing installed):
#
#   python3-skimage 0.19.3    16 photos of its data folder: astronaut, brick,
#                             camera, chelsea, coffee, coins, grass, gravel,
#                             hubble_deep_field, moon, rocket, retina, ihc, cell,
#                             clock_motion, page. Never motorcycle_*: that stereo
#                             pair is bench/motorcycle_check.sh's evaluation data.
#   lomiri-wallpapers-16.04,  13 photographs (landscapes, plants, objects,
#   lomiri-wallpapers-20.04   interiors; CC-BY / CC-BY-SA / CC0 by their
#                             photographers, see the packages' copyright files);
#                             the packages' graphic, non-photographic
#                             wallpapers are left out.
#
#   train/fetch_photos.sh DIR [--skimage_only]
#
# --skimage_only gives the 16-photo folder of the earlier training stages.
# Stereo and multi-view benchmark images that packages happen to ship are
# never used: they are kept for evaluation.
set -euo pipefail
dir=${1:?usage: train/fetch_photos.sh DIR [--skimage_only]}
skimage_only=0
[ "${2:-}" = "--skimage_only" ] && skimage_only=1
mkdir -p "$dir"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cd "$scratch"

apt-get download python3-skimage > /dev/null
dpkg-deb -x python3-skimage_*.deb pkg
data=$(dirname "$(find pkg -path '*skimage/data/astronaut.png' | head -1)")
for name in astronaut.png brick.png camera.png chelsea.png coffee.png coins.png grass.png gravel.png \
            hubble_deep_field.jpg moon.png rocket.jpg retina.jpg ihc.png cell.png clock_motion.png page.png; do
  cp "$data/$name" "$dir/"
done

if [ "$skimage_only" = 0 ]; then
  apt-get download lomiri-wallpapers-16.04 lomiri-wallpapers-20.04 > /dev/null
  for deb in lomiri-wallpapers-*.deb; do dpkg-deb -x "$deb" pkg; done
  for name in Bridge_by_Sander_Klootwijk Dragonfly_by_Bolly Picture_0B_by_freespace Picture_1A_by_freespace \
              Wine_by_Jakkub_Mede aitzgorri_by_Aitzol_Berasategi free_by_Peter_Nerlich \
              friends_by_Aitzol_Berasategi life_by_Aitzol_Berasategi picosdeeuropa_by_Aitzol_Berasategi \
              seeding_by_Clements_Engelhardt sunset_by_Aitzol_Berasategi Kleiber_by_Lukas_Baubkus; do
    cp "$(find pkg -name "$name.jpg" | head -1)" "$dir/"
  done
fi
echo "$(find "$dir" -maxdepth 1 -type f | wc -l) photos in $dir"
