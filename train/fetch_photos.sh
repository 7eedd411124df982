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
#   mate-backgrounds 1.26     the 12 photographs of its nature folder (grass,
#                             leaves, flowers, wood, water; GPL-2+).
#   plasma-workspace-         8 photographs with texture from edge to edge
#   wallpapers 5.27           (jetty, boats, cups, leaves, forest path,
#                             architecture; LGPL-3), at 1920x1080 where the
#                             package has that size; its drawings and renders,
#                             and the photos that are mostly sky or fog, are
#                             left out.
#
#   train/fetch_photos.sh DIR [--set photos49 | photos29 | skimage16]
#
# photos49 (the default): all four sources, for stages from 14 on.
# photos29: python3-skimage and lomiri, the folder of stages 5-13.
# skimage16 (or the older spelling --skimage_only): python3-skimage alone,
# the folder of stages 2-4.
# Stereo and multi-view benchmark images that packages happen to ship are
# never used: they are kept for evaluation.
set -euo pipefail
usage="usage: train/fetch_photos.sh DIR [--set photos49 | photos29 | skimage16]"
dir=${1:?$usage}
set_name=photos49
case "${2:-}" in
  "") ;;
  --skimage_only) set_name=skimage16 ;;
  --set) set_name=${3:?$usage} ;;
  *) echo "$usage" >&2; exit 2 ;;
esac
case "$set_name" in
  photos49|photos29|skimage16) ;;
  *) echo "unknown photo set '$set_name'; $usage" >&2; exit 2 ;;
esac
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

if [ "$set_name" != skimage16 ]; then
  apt-get download lomiri-wallpapers-16.04 lomiri-wallpapers-20.04 > /dev/null
  for deb in lomiri-wallpapers-*.deb; do dpkg-deb -x "$deb" pkg; done
  for name in Bridge_by_Sander_Klootwijk Dragonfly_by_Bolly Picture_0B_by_freespace Picture_1A_by_freespace \
              Wine_by_Jakkub_Mede aitzgorri_by_Aitzol_Berasategi free_by_Peter_Nerlich \
              friends_by_Aitzol_Berasategi life_by_Aitzol_Berasategi picosdeeuropa_by_Aitzol_Berasategi \
              seeding_by_Clements_Engelhardt sunset_by_Aitzol_Berasategi Kleiber_by_Lukas_Baubkus; do
    cp "$(find pkg -name "$name.jpg" | head -1)" "$dir/"
  done
fi

if [ "$set_name" = photos49 ]; then
  apt-get download mate-backgrounds plasma-workspace-wallpapers > /dev/null
  for deb in mate-backgrounds_*.deb plasma-workspace-wallpapers_*.deb; do dpkg-deb -x "$deb" pkg; done
  nature=pkg/usr/share/backgrounds/mate/nature
  for name in Aqua Blinds Dune FreshFlower Garden GreenMeadow LadyBird RainDrops Storm TwoWings Wood YellowFlower; do
    cp "$nature/$name.jpg" "$dir/mate_$name.jpg"
  done
  for name in BytheWater ColdRipple ColorfulCups EveningGlow FallenLeaf Grey OneStandsOut Path; do
    images=pkg/usr/share/wallpapers/$name/contents/images
    photo=$images/1920x1080.jpg
    [ -e "$photo" ] || photo=$(find "$images" -name '*.jpg' | sort | head -1)
    cp "$photo" "$dir/plasma_$name.jpg"
  done
fi
echo "$(find "$dir" -maxdepth 1 -type f | wc -l) photos in $dir"
