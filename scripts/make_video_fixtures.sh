#!/usr/bin/env bash
# MP4 fixtures made by another project's code (ffmpeg with libx264 / libx265 / its MPEG-4
# encoder), for crates/video/tests/video/ffmpeg_fixtures.rs. Needs ffmpeg (Debian: apt install ffmpeg);
# the outputs are committed, so tests and CI do not need ffmpeg.
#
#   x264_high_bframes.mp4  H.264 High profile, CABAC, 2 B-frames, 8x8 transform, 160x96, 12 frames
#                          at 25 fps, plus an AAC audio track (the reader must pick the video)
#   x264_high_bframes/     ffmpeg's own decode of it to 8-bit RGB PNG frames (the reference)
#   x264_baseline_30fps.mp4 H.264 constrained baseline, 96x64, 9 frames at 30000/1001 fps
#   hevc.mp4               HEVC ('hvc1'): must be a typed codec error
#   mpeg4.mp4              MPEG-4 part 2 ('mp4v'): must be a typed codec error
#   fragmented.mp4         H.264 in fragmented MP4 (moof): must be a typed error
set -euo pipefail
out="$(dirname "$0")/../crates/video/tests/fixtures"
mkdir -p "$out"
src=(-f lavfi -i "testsrc2=size=160x96:rate=25:duration=0.48")
ff() { ffmpeg -hide_banner -loglevel error -y "$@"; }
ff "${src[@]}" -f lavfi -i "sine=frequency=440:duration=0.48" \
  -c:v libx264 -profile:v high -bf 2 -pix_fmt yuv420p -crf 18 -c:a aac -shortest \
  "$out/x264_high_bframes.mp4"
rm -rf "$out/x264_high_bframes" && mkdir -p "$out/x264_high_bframes"
ff -i "$out/x264_high_bframes.mp4" -pix_fmt rgb24 "$out/x264_high_bframes/frame_%03d.png"
ff -f lavfi -i "testsrc2=size=96x64:rate=30000/1001:duration=0.3" \
  -c:v libx264 -profile:v baseline -pix_fmt yuv420p -crf 20 "$out/x264_baseline_30fps.mp4"
ff "${src[@]}" -c:v libx265 -tag:v hvc1 -pix_fmt yuv420p -x265-params log-level=error "$out/hevc.mp4"
ff "${src[@]}" -c:v mpeg4 "$out/mpeg4.mp4"
ff "${src[@]}" -c:v libx264 -pix_fmt yuv420p -movflags frag_keyframe+empty_moov "$out/fragmented.mp4"
ls -l "$out"
