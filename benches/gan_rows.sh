# The rows of the GAN-step tables, sourced by benches/compare_gan_peer.sh and
# benches/gan_step_settings.sh so both measure the same steps. ROWS=base|hd|all picks them
# into the array ROWS.
BASE_ROWS=(
  "generator --size 28 --channels 32 --layers 5"
  "generator --size 40 --channels 32 --layers 5"
  "generator --size 53 --channels 32 --layers 5"
  "generator --size 71 --channels 32 --layers 5"
  "critic --size 54 --batch 2 --channels 32 --layers 5"
  "critic --size 108 --batch 2 --channels 32 --layers 5"
)
# The hd preset's finest costs: the finer scales' generator on the active set, the critics of
# its 160^2 renderings and of the upsampler's 320^2 pictures (6 channels), 16 channels each.
HD_ROWS=(
  "active --size 95 --channels 16 --layers 5"
  "active --size 126 --channels 16 --layers 5"
  "critic --size 160 --batch 2 --channels 16 --layers 5"
  "critic --size 320 --batch 2 --channels 16 --layers 5 --in-channels 6"
)
case "${ROWS:-all}" in
  base) ROWS=("${BASE_ROWS[@]}") ;;
  hd) ROWS=("${HD_ROWS[@]}") ;;
  *) ROWS=("${BASE_ROWS[@]}" "${HD_ROWS[@]}") ;;
esac
