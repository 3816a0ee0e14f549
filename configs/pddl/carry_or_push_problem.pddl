; Two skeletons reach the goal (unit action costs):
;   push  (cost 3): move_to(PushSide) push(Cube_push) move_to(Exit)
;   carry (cost 5): move_to(Table1) grasp(Cube_g) move_to(Box) place(Cube_p) move_to(Exit)
; A site names where the base parks and what is in reach from there: the cube
; starts on the table (reached from loc_table1); pushed off the edge it lands in
; the box (reached from loc_box).
(define (problem carry-or-push-demo)
  (:domain carry-or-push)
  (:objects
    Table1 PushSide Box Exit - base_region
    Cube_g - grasp_region
    Cube_p - place_region
    Cube_push - push_region
    loc_start loc_table1 loc_push loc_box loc_exit - site
    cube1 - cube)
  (:init
    (robot-at loc_start)
    (hand-empty)
    (cube-at cube1 loc_table1)
    (road loc_start loc_table1) (road loc_table1 loc_box) (road loc_box loc_exit)
    (road loc_start loc_push) (road loc_push loc_exit)
    (base-near Table1 loc_table1)
    (base-near PushSide loc_push)
    (base-near Box loc_box)
    (base-near Exit loc_exit)
    (grasps Cube_g cube1)
    (place-on Cube_p loc_box)
    (pushes Cube_push cube1 loc_push loc_table1 loc_box))
  (:goal (and (cube-at cube1 loc_box) (robot-at loc_exit))))
