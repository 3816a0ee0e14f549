; Three skeletons reach the goal (unit action costs):
;   push        (2 actions): move_to(PushSide) push(Stick_p)
;   carry       (3 actions): move_to(StickSide) grasp(Cube_g) place(Cube_p)
;   carry+drive (4 actions): move_to(StickSide) grasp(Cube_g) move_to(BoxSide) place(Cube_p)
; From loc_stick (beside the stick and the box) the arm reaches both the stick top and the box;
; from loc_box (south-east of the box) only the box; from loc_push (behind the stick, opposite
; the box) a push drops the cube into the box.
; Symbolically push is cheaper; in scene=carry_or_push it is not once realized (long drive).
(define (problem carry-or-push-demo)
  (:domain carry-or-push)
  (:objects
    PushSide StickSide BoxSide - base_region
    Cube_g - grasp_region
    Cube_p - place_region
    Stick_p - push_region
    loc_start loc_stick loc_push loc_box - site
    stick_top box_inside - spot
    stick cube - item)   ; named as in scene.objects
  (:init
    (robot-at loc_start)
    (hand-empty)
    (item-at cube stick_top)
    (road loc_start loc_stick) (road loc_start loc_push) (road loc_stick loc_box)
    (base-near StickSide loc_stick)
    (base-near PushSide loc_push)
    (base-near BoxSide loc_box)
    (reach loc_stick stick_top) (reach loc_stick box_inside) (reach loc_box box_inside)
    (grasps Cube_g stick_top)
    (place-on Cube_p box_inside)
    (pushes Stick_p stick loc_push stick_top box_inside))
  (:goal (item-at cube box_inside)))
